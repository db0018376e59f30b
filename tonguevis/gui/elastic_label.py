"""A label and a combo box whose long texts never widen the window, yet show whole where there is room."""

from __future__ import annotations

from PySide6.QtCore import QSize
from PySide6.QtWidgets import QComboBox, QLabel


class ElasticLabel(QLabel):
    """A one-line QLabel that asks for its text's width but needs only ``minimum_width`` pixels.

    A plain QLabel's minimum width is its text's: a status line that grows by a word at some
    frame raises the window's minimum width, and the window (and with it the 3D views, which
    then render at their new size) resizes in the middle of playback.  This one is cut at the
    right edge instead when the window is narrower than its text.
    """

    def __init__(self, text: str = "", minimum_width: int = 120, parent=None):
        super().__init__(text, parent)
        self._minimum_width = int(minimum_width)

    def minimumSizeHint(self) -> QSize:  # noqa: N802 (Qt name)
        hint = super().minimumSizeHint()
        return QSize(min(hint.width(), self._minimum_width), hint.height())


class ElasticComboBox(QComboBox):
    """A QComboBox that asks for its longest entry's width but needs only ``minimum_characters``.

    With room (a wide window) the closed box shows its entries whole, e.g. "head frame (jaw
    moving, palate fixed)"; in a narrow window it is cut rather than widening the window past
    a laptop's screen (the list, when open, shows the entries whole either way).
    """

    def __init__(self, minimum_characters: int = 14, parent=None):
        super().__init__(parent)
        self.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToContents)
        self._minimum_characters = int(minimum_characters)

    def minimumSizeHint(self) -> QSize:  # noqa: N802 (Qt name)
        hint = super().minimumSizeHint()
        arrow = max(hint.width() - self._longest_text_width(), 0)  # frame, arrow and margins
        width = self.fontMetrics().horizontalAdvance("x" * self._minimum_characters) + arrow
        return QSize(min(hint.width(), width), hint.height())

    def _longest_text_width(self) -> int:
        metrics = self.fontMetrics()
        return max((metrics.horizontalAdvance(self.itemText(i)) for i in range(self.count())), default=0)
