"""Layout at 1280 x 800, a laptop's screen (issue 37, item 2): the window fits the screen, with a recording
compared beside too, and no status line, bar label or button is cut: each shows whole, or elided with the
whole text in its tooltip; rows of controls wrap and the live window's panel scrolls only up and down."""

from __future__ import annotations

import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import demo_session, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(240)]

SCREEN = (1280, 800)


def _cut(widget) -> str | None:
    """Why ``widget`` (a label, combo box or button) shows less than its text, or None when it shows it all
    (whole, or elided with the whole text in its tooltip)."""
    from PySide6.QtWidgets import QAbstractButton, QComboBox, QLabel

    metrics = widget.fontMetrics()
    if hasattr(widget, "is_elided"):  # an ElasticLabel: elided where it must be
        if widget.is_elided() and widget.plain_text() not in widget.shown_tooltip():
            return f"elided without its text in the tooltip: {widget.plain_text()!r}"
        return None
    if isinstance(widget, QLabel):
        if widget.wordWrap() and widget.text():  # wrapped: it must be as tall as its lines at its width
            need = QLabel.heightForWidth(widget, widget.contentsRect().width())
            # as tall as its lines, and shown so by its parent (a group box shorter than its rows clips them)
            shown = widget.contentsRect().height()
            if widget.parentWidget() is not None:
                shown = min(shown, widget.parentWidget().rect().bottom() - widget.geometry().top())
            if need > shown + 1:
                return f"wrapped text cut to {shown} of its {need} px: {widget.text()!r}"
            return None
        if not widget.text() or widget.textFormat() == widget.textFormat().RichText:
            return None
        room = widget.contentsRect().width() - 2 * widget.margin() - max(widget.indent(), 0)
        widest = max(metrics.horizontalAdvance(line) for line in widget.text().split("\n"))
        return f"cut: {widget.text()!r} ({widest} px in {room})" if widest > room else None
    if isinstance(widget, QComboBox):
        if widget.width() >= widget.sizeHint().width():
            return None
        tip = widget.shown_tooltip() if hasattr(widget, "shown_tooltip") else widget.toolTip()
        return None if widget.currentText() in tip else f"combo elided without a tooltip: {widget.currentText()!r}"
    if isinstance(widget, QAbstractButton):
        return f"button cut: {widget.text()!r}" if widget.width() < widget.sizeHint().width() else None
    return None


def _problems(window, containers) -> list[str]:
    """Every label, combo and button of ``containers`` that is cut, or lies past the window's right edge."""
    from PySide6.QtCore import QPoint
    from PySide6.QtWidgets import QAbstractButton, QComboBox, QLabel, QWidget

    found = []
    for name, container in containers.items():
        for widget in [container, *container.findChildren(QWidget)]:
            if not isinstance(widget, (QLabel, QComboBox, QAbstractButton)) or not widget.isVisible():
                continue
            why = _cut(widget)
            right = widget.mapTo(window, QPoint(widget.width(), 0)).x()
            if right > window.width() + 1:
                why = f"{right - window.width()} px past the window's edge"
            if why:
                found.append(f"{name}: {type(widget).__name__} {why}")
    return found


def _status_message_cut(window) -> str | None:
    """Why the status bar's message is not readable, or None (a QStatusBar draws its message itself, clipped
    where the permanent widgets begin: "0 not c" at 1280 pixels)."""
    from PySide6.QtWidgets import QWidget

    bar = window.statusBar()
    label = getattr(bar, "message", None)
    if label is not None:
        return _cut(label)
    permanent = sum(w.width() for w in bar.findChildren(QWidget) if w.parent() is bar and w.isVisible())
    room = bar.width() - permanent
    text = bar.currentMessage()
    return f"message cut to {room} px" if bar.fontMetrics().horizontalAdvance(text) > room else None


def _bars(window) -> dict:
    """The status bar, the 3D views' bar (the views themselves draw no Qt widgets), the transport and,
    when open, the compare pane's header."""
    bars = {"status bar": window.statusBar(), "3D bar": window.view3d, "transport": window.transport}
    if window.compare_panel.isVisible():
        bars["compare pane"] = window.compare_panel
    return bars


def _at_1280(qtbot, window):
    window.resize(*SCREEN)
    qtbot.waitUntil(lambda: window.width() <= SCREEN[0] and window.view3d.width() > 0, timeout=5000)
    qtbot.wait(100)


def test_the_window_and_its_bars_fit_a_1280_by_800_screen(qtbot, window):
    show_and_simulate(qtbot, window, demo_session())
    _at_1280(qtbot, window)
    assert window.minimumSizeHint().width() <= SCREEN[0] and window.width() == SCREEN[0]
    # The status line after a simulation is long (the summary's notes): elided, whole in the tooltip.
    message = window.statusBar().currentMessage()
    assert "frames simulated" in message and _status_message_cut(window) is None
    assert _problems(window, _bars(window)) == []
    for tab in range(window.tabs.count()):  # every tab fits beside the views (their rows wrap)
        window.tabs.setCurrentIndex(tab)
        qtbot.wait(20)
        assert window.width() == SCREEN[0], window.tabs.tabText(tab)
        assert _problems(window, {window.tabs.tabText(tab): window.tabs.currentWidget()}) == []


def test_with_a_recording_compared_beside_it_still_fits(qtbot, window):
    show_and_simulate(qtbot, window, demo_session())
    with qtbot.waitSignal(window.compare_finished, timeout=60000) as blocker:
        assert window.open_compare(demo_session(3.5, 6.8).path)
    assert blocker.args == [True], window.statusBar().currentMessage()
    _at_1280(qtbot, window)
    assert window.compare_panel.isVisible()
    assert window.minimumSizeHint().width() <= SCREEN[0] and window.width() == SCREEN[0]
    assert _problems(window, _bars(window)) == []


def test_the_live_panel_scrolls_only_up_and_down_and_shows_its_connect_button(qtbot, tmp_path):
    from PySide6.QtCore import QPoint
    from PySide6.QtWidgets import QScrollArea

    from tonguevis.gui.live_window import LiveWindow
    from tonguevis.live.session import LiveSession
    from tonguevis.live.source import WaveFrontSource

    window = LiveWindow(WaveFrontSource("127.0.0.1", 9, max_retries=0), LiveSession(profiles_root=tmp_path / "profiles"))
    window.quiet = True
    qtbot.addWidget(window)
    window.show()
    try:
        window.resize(*SCREEN)
        qtbot.wait(200)
        scroll = window.findChildren(QScrollArea)[0]
        assert not scroll.horizontalScrollBar().isVisible()
        assert scroll.widget().width() <= scroll.viewport().width()
        button = window.connect_button
        right = button.mapTo(scroll.viewport(), QPoint(button.width(), 0)).x()
        assert right <= scroll.viewport().width() and _cut(button) is None
        assert _problems(window, {"live panel": scroll.widget()}) == []
        # The rest's line once a rest is taken (three lines at this width: it was cut to one and a half).
        window.rest_label.setText("rest (stillest moment): 0.03-0.53 s after the first frame: 5 sensors drive the "
                                  "tongue (TT, TB, TD, TL, TR); JAW and the head references are used as given")
        window.connection_label.setText("streaming: 832 frames — connected to 127.0.0.1:38493")
        qtbot.wait(100)
        assert _problems(window, {"live panel": scroll.widget()}) == []
    finally:
        window.close_source()
        window.close()

