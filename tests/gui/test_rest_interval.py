"""The app's rest interval: shown after every simulation, set from Simulation ▸ Set rest interval…"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import demo_session, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


@pytest.fixture(autouse=True)
def _modes(window):
    """40 modes: enough for the block model to follow the demo plausibly (20 are refused as implausible)."""
    window.modes = 40


def _menu_action(window, menu_title: str, text: str):
    for menu_action in window.menuBar().actions():
        if menu_action.text() == menu_title:
            return next(a for a in menu_action.menu().actions() if a.text() == text)
    raise AssertionError(f"no menu {menu_title}")


def test_the_rest_found_is_in_the_status_bar(qtbot, window):
    session = show_and_simulate(qtbot, window, demo_session())  # 1.5 s of rest, then a train
    assert session.rest.how == "detected"
    assert session.motion.metadata["rest"]["how"] == "detected"
    assert window.rest_label.text() == session.rest.describe()
    assert "press Space to play" in window.statusBar().currentMessage()


def test_speech_from_the_first_frame_uses_the_stillest_window_and_says_so(qtbot, window):
    session = show_and_simulate(qtbot, window, demo_session(5.2, 7.5))  # no rest at all, 2.3 s
    assert session.rest.how == "stillest window"
    assert "stillest window: no still second in the recording" in window.rest_label.text()


def test_rest_dialog_checks_the_interval_and_resimulates(qtbot, window):
    from tonguevis.gui.rest_dialog import RestIntervalDialog

    session = show_and_simulate(qtbot, window, demo_session())
    first_motion = session.motion
    _menu_action(window, "&Simulation", "Set &rest interval…").trigger()
    dialog = window.last_dialog
    assert isinstance(dialog, RestIntervalDialog) and dialog.isVisible()
    # Prefilled with the rest in use; the spin boxes span the recording.
    assert dialog.start.value() == pytest.approx(session.rest.interval[0], abs=0.006)
    assert dialog.start.minimum() == pytest.approx(session.recording.times[0])
    assert dialog.end.maximum() == pytest.approx(session.recording.times[-1])
    # End before start: the dialog names the problem and stays open; nothing is simulated.
    dialog.start.setValue(4.5)
    dialog.end.setValue(4.0)
    dialog._check_and_accept()
    assert "the end must come after the start" in dialog.problem.text()
    assert dialog.isVisible() and session.motion is first_motion
    # A good interval: accepted, simulated again through the worker, reported as given.
    dialog.end.setValue(4.9)
    with qtbot.waitSignal(window.simulation_finished, timeout=60000) as blocker:
        dialog._check_and_accept()
    assert blocker.args == [True]
    assert session.given_rest == (4.5, 4.9)
    assert session.rest.interval == (4.5, 4.9) and session.rest.how == "given"
    assert session.motion is not first_motion
    assert window.rest_label.text() == "rest: 4.50-4.90 s (given)"
    # Find automatically: back to the detected rest.
    window.ask_rest_interval()
    with qtbot.waitSignal(window.simulation_finished, timeout=60000):
        window.last_dialog.auto_button.click()
    assert session.given_rest is None and session.rest.how == "detected"


def test_rest_dialog_refuses_an_interval_without_valid_samples(qtbot, window):
    session = demo_session()
    tip = session.recording.sensors["TT"]
    tip[(session.recording.times > 3.9) & (session.recording.times < 4.4)] = np.nan  # a dropout at rest
    show_and_simulate(qtbot, window, session)
    window.ask_rest_interval()
    dialog = window.last_dialog
    dialog.start.setValue(4.0)
    dialog.end.setValue(4.3)
    dialog._check_and_accept()
    assert "no valid sample of TT" in dialog.problem.text() and dialog.isVisible()
    dialog.reject()


def test_a_bad_interval_given_in_code_is_a_dialog_not_a_crash(qtbot, window):
    from PySide6.QtWidgets import QMessageBox

    session = show_and_simulate(qtbot, window, demo_session())
    motion = session.motion
    assert window.set_rest_interval((100.0, 101.0)) is False
    box = window.last_dialog
    assert isinstance(box, QMessageBox) and "not inside the recording" in box.text()
    assert "Rest interval not usable" in window.statusBar().currentMessage()
    assert session.given_rest is None and session.motion is motion
    box.close()


def test_opening_with_a_bad_rest_names_the_problem(qtbot, window, tmp_path):
    from PySide6.QtWidgets import QMessageBox

    from tests.gui.conftest import DEMO

    if not DEMO.exists():
        pytest.skip("demo corpus not built")
    assert window.open_recording(DEMO, rest=(5.0, 3.0)) is False
    assert window.session is None
    box = window.last_dialog
    assert isinstance(box, QMessageBox) and "the end must come after the start" in box.text()
    box.close()


def test_set_rest_without_a_recording_says_so(qtbot, window):
    window.ask_rest_interval()
    assert "open a recording first" in window.last_dialog.text()
    window.last_dialog.close()
