"""The app's rest interval: shown after every simulation, set from Simulation ▸ Set rest interval…;
``tonguevis view`` and ``export-video`` on recordings without a rest, with --rest, with a bad --rest."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import demo_session, show_and_simulate  # noqa: E402
from tests.test_cli_rest import REAL, STILLEST, generated, recording, run  # noqa: E402,F401 (generated: a fixture)

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


@pytest.fixture
def win(window):
    """The test window with 40 modes: enough for the block model to follow the demo plausibly."""
    window.modes = 40
    return window


def _menu_action(win, menu_title: str, text: str):
    for menu_action in win.menuBar().actions():
        if menu_action.text() == menu_title:
            return next(a for a in menu_action.menu().actions() if a.text() == text)
    raise AssertionError(f"no menu {menu_title}")


def test_the_rest_found_is_in_the_status_bar(qtbot, win):
    session = show_and_simulate(qtbot, win, demo_session())  # 1.5 s of rest, then a train
    assert session.rest.how == "detected"
    assert session.motion.metadata["rest"]["how"] == "detected"
    assert win.rest_label.text() == session.rest.describe()
    assert "press Space to play" in win.statusBar().currentMessage()


def test_speech_from_the_first_frame_uses_the_stillest_window_and_says_so(qtbot, win):
    session = show_and_simulate(qtbot, win, demo_session(5.2, 7.5))  # no rest at all, 2.3 s
    assert session.rest.how == "stillest window"
    assert "stillest window: no still second in the recording" in win.rest_label.text()


def test_rest_dialog_checks_the_interval_and_resimulates(qtbot, win):
    from tonguevis.gui.rest_dialog import RestIntervalDialog

    session = show_and_simulate(qtbot, win, demo_session())
    first_motion = session.motion
    _menu_action(win, "&Simulation", "Set &rest interval…").trigger()
    dialog = win.last_dialog
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
    with qtbot.waitSignal(win.simulation_finished, timeout=60000) as blocker:
        dialog._check_and_accept()
    assert blocker.args == [True]
    assert session.given_rest == (4.5, 4.9)
    assert session.rest.interval == (4.5, 4.9) and session.rest.how == "given"
    assert session.motion is not first_motion
    assert win.rest_label.text() == "rest: 4.50-4.90 s (given)"
    # Find automatically: back to the detected rest.
    win.ask_rest_interval()
    with qtbot.waitSignal(win.simulation_finished, timeout=60000):
        win.last_dialog.auto_button.click()
    assert session.given_rest is None and session.rest.how == "detected"


def test_rest_dialog_refuses_an_interval_without_valid_samples(qtbot, win):
    session = demo_session()
    tip = session.recording.sensors["TT"]
    tip[(session.recording.times > 3.9) & (session.recording.times < 4.4)] = np.nan  # a dropout at rest
    show_and_simulate(qtbot, win, session)
    win.ask_rest_interval()
    dialog = win.last_dialog
    dialog.start.setValue(4.0)
    dialog.end.setValue(4.3)
    dialog._check_and_accept()
    assert "no valid sample of TT" in dialog.problem.text() and dialog.isVisible()
    dialog.reject()


def test_a_bad_interval_given_in_code_is_a_dialog_not_a_crash(qtbot, win):
    from PySide6.QtWidgets import QMessageBox

    session = show_and_simulate(qtbot, win, demo_session())
    motion = session.motion
    assert win.set_rest_interval((100.0, 101.0)) is False
    box = win.last_dialog
    assert isinstance(box, QMessageBox) and "not inside the recording" in box.text()
    assert "Rest interval not usable" in win.statusBar().currentMessage()
    assert session.given_rest is None and session.motion is motion
    box.close()


def test_opening_with_a_bad_rest_names_the_problem(qtbot, win, tmp_path):
    from PySide6.QtWidgets import QMessageBox

    from tests.gui.conftest import DEMO

    if not DEMO.exists():
        pytest.skip("demo corpus not built")
    assert win.open_recording(DEMO, rest=(5.0, 3.0)) is False
    assert win.session is None
    box = win.last_dialog
    assert isinstance(box, QMessageBox) and "the end must come after the start" in box.text()
    box.close()


def test_set_rest_without_a_recording_says_so(qtbot, win):
    win.ask_rest_interval()
    assert "open a recording first" in win.last_dialog.text()
    win.last_dialog.close()


def _video(path, out, *options):
    return ["export-video", path, *options, "--out", out, "--start", "0.5", "--end", "0.8", "--size", "320x240",
            "--fps", "10", "--quiet"]


@pytest.mark.slow
@pytest.mark.parametrize("which", ["speech-from-first-frame", "under-3-s", *REAL])
def test_view_and_export_video_find_a_rest_and_say_which(which, generated, tmp_path, capsys):
    path, options = recording(which, generated)
    shot, video = tmp_path / "v.png", tmp_path / "v.mp4"
    code, out, err = run(capsys, "view", path, *options, "--screenshot", shot)
    assert code == 0, err[-2000:]
    assert STILLEST.search(out) and shot.stat().st_size > 10_000, out
    code, out, err = run(capsys, *_video(path, video, *options))
    assert code == 0, err[-2000:]
    assert STILLEST.search(out) and video.stat().st_size > 1000, out


@pytest.mark.slow
def test_view_and_export_video_use_a_given_rest_and_refuse_a_bad_one(generated, tmp_path, capsys):
    path = generated["under-3-s"]
    code, out, err = run(capsys, "view", path, "--rest", "0.3", "0.6", "--screenshot", tmp_path / "v.png")
    assert code == 0 and "rest: 0.30-0.60 s (given)" in out, err[-2000:]
    code, out, err = run(capsys, *_video(path, tmp_path / "v.mp4", "--rest", "0.3", "0.6"))
    assert code == 0 and "rest: 0.30-0.60 s (given)" in out, err[-2000:]
    for rest, problem in ((("1", "9"), "is not inside the recording"), (("0.6", "0.3"), "the end must come after")):
        for argv in (["view", path, "--rest", *rest, "--screenshot", tmp_path / "x.png"],
                     _video(path, tmp_path / "x.mp4", "--rest", *rest)):
            code, out, err = run(capsys, *argv)
            lines = err.strip().splitlines()
            assert code == 2 and len(lines) == 1, (argv, err)
            assert path.name in lines[0] and problem in lines[0], lines[0]
        assert not (tmp_path / "x.png").exists() and not (tmp_path / "x.mp4").exists()
