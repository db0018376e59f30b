"""Labels, combo boxes and a status bar whose long texts never widen the window, yet show whole where
there is room, and are elided ("…") with the whole text in their tooltip where there is not."""

from __future__ import annotations

from PySide6.QtCore import QSize, Qt, QTimer
from PySide6.QtGui import QPainter, QTextDocumentFragment
from PySide6.QtGui import Qt as GuiQt
from PySide6.QtWidgets import QComboBox, QLabel, QStatusBar, QWidget


class _WholeTextTip:
    """A tooltip that begins with the widget's whole text (:meth:`_whole_text`, "" for none) before the
    tooltip given with ``setToolTip`` (which ``toolTip`` returns; ``shown_tooltip`` is the one shown)."""

    _base_tip = ""

    def setToolTip(self, tip: str) -> None:  # noqa: N802 (Qt name)
        self._base_tip = tip
        self._update_tip()

    def toolTip(self) -> str:  # noqa: N802 (Qt name)
        return self._base_tip

    def shown_tooltip(self) -> str:
        return QWidget.toolTip(self)

    def _whole_text(self) -> str:
        raise NotImplementedError

    def _update_tip(self) -> None:
        QWidget.setToolTip(self, "\n\n".join(t for t in (self._whole_text(), self._base_tip) if t))


class ElasticLabel(_WholeTextTip, QLabel):
    """A one-line QLabel that asks for its text's width but needs only ``minimum_width`` pixels.

    A plain QLabel's minimum width is its text's: a status line that grows by a word at some
    frame raises the window's minimum width, and the window (and with it the 3D views, which
    then render at their new size) resizes in the middle of playback.  This one is elided at
    its right end instead when the window is narrower than its text, and its tooltip then
    holds the whole text (before the tooltip given with :meth:`setToolTip`, if any).
    ``text()`` is always the whole text.
    """

    def __init__(self, text: str = "", minimum_width: int = 120, parent=None):
        super().__init__(text, parent)
        self._minimum_width = int(minimum_width)
        self._base_tip = ""
        self._update_tip()

    def minimumSizeHint(self) -> QSize:  # noqa: N802 (Qt name)
        hint = super().minimumSizeHint()
        return QSize(min(hint.width(), self._minimum_width), hint.height())

    def plain_text(self) -> str:
        """The whole text without its markup (``<b>B</b>: spk2_ta`` -> ``B: spk2_ta``)."""
        text = self.text()
        return QTextDocumentFragment.fromHtml(text).toPlainText() if GuiQt.mightBeRichText(text) else text

    def shown_text(self) -> str:
        """The text as painted (without markup): whole, or elided to the label's width."""
        width = self.contentsRect().width() - 2 * self.margin() - max(self.indent(), 0)
        return self.fontMetrics().elidedText(self.plain_text(), Qt.TextElideMode.ElideRight, max(width, 0))

    def is_elided(self) -> bool:
        return self.shown_text() != self.plain_text()

    def setText(self, text: str) -> None:  # noqa: N802 (Qt name)
        super().setText(text)
        self._update_tip()

    def resizeEvent(self, event) -> None:  # noqa: N802 (Qt name)
        super().resizeEvent(event)
        self._update_tip()

    def paintEvent(self, event) -> None:  # noqa: N802 (Qt name)
        shown = self.shown_text()
        if shown == self.plain_text():
            super().paintEvent(event)
            return
        painter = QPainter(self)
        self.style().drawItemText(painter, self.contentsRect().adjusted(self.margin(), self.margin(), -self.margin(),
                                                                        -self.margin()),
                                  int(self.alignment()), self.palette(), self.isEnabled(), shown, self.foregroundRole())

    def _whole_text(self) -> str:  # in the tooltip when elided
        return self.plain_text() if self.is_elided() else ""


class WrappingLabel(QLabel):
    """A word-wrapped QLabel that is never shorter than its lines at its width.

    A wrapped QLabel's minimum height is that of its text wrapped at some other width: in a panel
    squeezed up and down (the live window's, under its views) the layout gave the rest's three
    lines 18 pixels.  This one asks for the height its text needs at the width it has.
    """

    def __init__(self, text: str = "", parent=None):
        super().__init__(text, parent)
        self.setWordWrap(True)

    def _remeasure(self) -> None:
        width = self.contentsRect().width()
        if width <= 0:
            return
        needed = self.heightForWidth(width) + self.height() - self.contentsRect().height()
        # An explicit minimum, which every layout above honours; only on a change, so a width that settles
        # stops here.
        if needed != self.minimumHeight():
            self.setMinimumHeight(needed)
            # and lay out again above it: in the live panel (a scroll area's body laid out by height for
            # width) the group kept its old height until something else moved, the rest's lines cut
            parent = self.parentWidget()
            while parent is not None and not parent.isWindow():
                if parent.layout() is not None:
                    parent.layout().invalidate()
                parent = parent.parentWidget()

    def setText(self, text: str) -> None:  # noqa: N802 (Qt name)
        super().setText(text)
        self._remeasure()

    def resizeEvent(self, event) -> None:  # noqa: N802 (Qt name)
        super().resizeEvent(event)
        self._remeasure()

    def hasHeightForWidth(self) -> bool:  # noqa: N802 (Qt name)
        # Its minimum height says it instead: the form and box layouts above, laying out by height for
        # width, gave the group the height of the text at another width (the rest's 3 lines cut to 1.5).
        return False


class ElasticComboBox(_WholeTextTip, QComboBox):
    """A QComboBox that asks for its longest entry's width but needs only ``minimum_characters``.

    With room (a wide window) the closed box shows its entries whole, e.g. "head frame (jaw
    moving, palate fixed)"; in a narrow window it is elided rather than widening the window past
    a laptop's screen (the list, when open, shows the entries whole either way), and its tooltip
    always begins with the entry shown, whole.
    """

    def __init__(self, minimum_characters: int = 14, parent=None):
        super().__init__(parent)
        self.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToContents)
        self._minimum_characters = int(minimum_characters)
        self._base_tip = ""
        self.currentIndexChanged.connect(lambda _i: self._update_tip())

    def _whole_text(self) -> str:  # always: the entry shown, whole
        return self.currentText()

    def minimumSizeHint(self) -> QSize:  # noqa: N802 (Qt name)
        hint = super().minimumSizeHint()
        arrow = max(hint.width() - self._longest_text_width(), 0)  # frame, arrow and margins
        width = self.fontMetrics().horizontalAdvance("x" * self._minimum_characters) + arrow
        return QSize(min(hint.width(), width), hint.height())

    def _longest_text_width(self) -> int:
        metrics = self.fontMetrics()
        return max((metrics.horizontalAdvance(self.itemText(i)) for i in range(self.count())), default=0)


class ElidingStatusBar(QStatusBar):
    """A status bar whose message is an :class:`ElasticLabel`: elided, whole in its tooltip, never cut.

    QStatusBar draws a message clipped where its permanent widgets begin ("0 not c" at 1280
    pixels); here the message is a widget of the bar's layout, which shares the width with the
    permanent widgets (each asking for its whole text, each elided when there is too little).
    ``showMessage``/``currentMessage``/``clearMessage`` work as QStatusBar's, with the whole text.
    """

    def __init__(self, parent=None):
        super().__init__(parent)
        self.message = ElasticLabel("", minimum_width=160)
        self.addWidget(self.message, 1)
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.timeout.connect(self.clearMessage)

    def showMessage(self, text: str, timeout: int = 0) -> None:  # noqa: N802 (Qt name)
        self.message.setText(text)
        self.setToolTip(text)  # the whole message over the whole bar too
        self._timer.stop()
        if timeout > 0:
            self._timer.start(int(timeout))

    def currentMessage(self) -> str:  # noqa: N802 (Qt name)
        return self.message.text()

    def clearMessage(self) -> None:  # noqa: N802 (Qt name)
        self.message.setText("")
        self.setToolTip("")
