"""The job runner and the app model: cancel works, a failure is a dialog, results come back to the
GUI thread (no worker assigns a window attribute or writes the app model), and the tabs talk through
the model only."""

from __future__ import annotations

from tonguevis.sim.settings import RunSettings

import threading
import time

import pytest

pytest.importorskip("PySide6")

from tests.gui.conftest import MODES, block_model, demo_session, show_and_simulate  # noqa: E402
from tonguevis.errors import TonguevisError  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(180)]


@pytest.fixture
def parent(qtbot):
    from PySide6.QtWidgets import QWidget

    from tonguevis.gui.worker import Job

    widget = QWidget()
    qtbot.addWidget(widget)
    widget.show()
    yield widget
    for job in widget.findChildren(Job):  # a failed test must not leave a thread running
        job.stop()


def _endless(progress):
    """Reports progress until cancelled (the job's progress callback raises Cancelled)."""
    for k in range(10 ** 6):
        progress(k % 100, 100, f"step {k}")
        time.sleep(0.005)
    return "never"


def test_a_partial_result_comes_to_the_gui_thread_and_gives_the_window_back(qtbot, parent):
    """A job handing over a first result: on_partial gets it on the GUI thread, the modal dialog closes
    and the rest of the progress goes to the status line; then the whole result as usual."""
    from tonguevis.gui.worker import Job, JobReactions, run_job

    release = threading.Event()
    partials, done, statuses = [], [], []

    def work(progress, partial):
        progress(1, 10, "first part")
        partial("first seconds")
        release.wait(10)
        time.sleep(2 * Job.MIN_INTERVAL)  # progress is sent at most every MIN_INTERVAL
        progress(7, 10, "the rest")
        return "whole"

    def on_partial(result):
        partials.append((result, threading.current_thread() is threading.main_thread(), job.dialog.isVisible()))

    job = run_job(parent, "Long", work, done.append, JobReactions(status=statuses.append, on_partial=on_partial),
                  min_duration_ms=0)
    qtbot.waitUntil(lambda: bool(partials), timeout=10000)
    assert partials == [("first seconds", True, True)]  # the dialog was up until the first result
    assert job.dialog is None and job.isRunning()  # given back while the job goes on
    with qtbot.waitSignal(job.ended, timeout=10000):
        release.set()
    assert done == ["whole"] and statuses == ["Long: the rest (70 %)"]


def test_cancel_stops_the_job_and_nothing_is_handed_back(qtbot, parent):
    from tonguevis.gui.worker import JobReactions, run_job

    done, statuses, ended = [], [], []
    job = run_job(parent, "Endless", _endless, done.append, JobReactions(status=statuses.append, on_ended=ended.append),
                  min_duration_ms=0)
    qtbot.waitUntil(lambda: job.dialog.value() > 0, timeout=10000)  # the dialog shows progress
    assert job.dialog.isVisible()
    from PySide6.QtWidgets import QPushButton

    (button,) = [b for b in job.dialog.findChildren(QPushButton) if b.text() == "Cancel"]
    with qtbot.waitSignal(job.ended, timeout=10000) as blocker:
        button.click()  # the dialog's Cancel button
    assert blocker.args == ["cancelled"] and job.outcome == "cancelled"
    assert not job.isRunning() and done == [] and ended == ["cancelled"]
    assert statuses == ["Endless: cancelled"]
    assert not job.dialog.isVisible()


def test_a_failure_becomes_a_dialog_naming_the_task_and_the_file(qtbot, parent, tmp_path):
    from PySide6.QtWidgets import QMessageBox

    from tonguevis.gui.worker import JobReactions, run_job

    def broken(progress):
        progress(1, 2, "half way")
        raise TonguevisError("the file has no samples")

    failed = []
    job = run_job(parent, "Reading", broken, lambda _r: pytest.fail("a failed job has no result"),
                  JobReactions(path=tmp_path / "x.tsv", explain=lambda m: m + "\n(try another file)",
                               on_failed=failed.append))
    with qtbot.waitSignal(job.ended, timeout=10000) as blocker:
        pass
    assert blocker.args == ["failed"] and failed == ["the file has no samples"]
    boxes = [b for b in parent.findChildren(QMessageBox) if b.isVisible()]
    assert len(boxes) == 1
    assert boxes[0].windowTitle() == "Reading failed"
    assert "the file has no samples" in boxes[0].text() and "x.tsv" in boxes[0].text()
    assert "(try another file)" in boxes[0].text()
    boxes[0].close()


def test_a_bug_in_a_job_is_a_dialog_too_and_the_window_keeps_it(qtbot, window):
    from tonguevis.gui.worker import run_job

    def buggy(progress):
        return {}["missing"]

    job = run_job(window, "Export", buggy)
    qtbot.waitUntil(lambda: job.outcome is not None and not job.isRunning(), timeout=10000)
    qtbot.waitUntil(lambda: window.last_dialog is not None, timeout=5000)
    assert window.last_dialog.windowTitle() == "Export failed"
    assert "unexpected KeyError" in window.last_dialog.text()
    assert "Export failed" in window.state.status  # the window's show_error writes the model's status
    window.last_dialog.close()


class _Threads:
    """Records which thread assigns the window's (and its simulation controller's) attributes and writes the
    app model."""

    def __init__(self, monkeypatch):
        from tonguevis.appstate import AppState
        from tonguevis.gui.controller import SimulationController
        from tonguevis.gui.window import MainWindow

        self.window_sets: list[tuple[str, bool]] = []
        self.events: list[tuple[str, bool]] = []
        set_attribute, emit = MainWindow.__setattr__, AppState._emit
        set_controller = SimulationController.__setattr__

        def recording_setattr(obj, name, value):
            self.window_sets.append((name, threading.current_thread() is threading.main_thread()))
            (set_controller if isinstance(obj, SimulationController) else set_attribute)(obj, name, value)

        def recording_emit(state, name, value, source, key=None):
            self.events.append((name, threading.current_thread() is threading.main_thread()))
            emit(state, name, value, source, key)

        monkeypatch.setattr(MainWindow, "__setattr__", recording_setattr)
        monkeypatch.setattr(SimulationController, "__setattr__", recording_setattr)
        monkeypatch.setattr(AppState, "_emit", recording_emit)

    def off_the_gui_thread(self) -> list:
        return [name for name, on_main in self.window_sets + self.events if not on_main]


def test_models_are_built_in_the_job_and_handed_back_to_the_gui_thread(qtbot, window, monkeypatch):
    """The simulation and the Energy tab's corpus build the tongue model they need in their job; it
    reaches the window and the app model on the GUI thread, and no worker assigns anything there."""
    import tonguevis.workflows.simulation as simulation
    from tests.gui.conftest import DEMO
    from tonguevis.gui.energy_tab import EnergyTab

    built: list[bool] = []

    def build_model(settings=None):
        built.append(threading.current_thread() is threading.main_thread())
        return block_model()

    import tonguevis.sim.settings as settings_module

    monkeypatch.setattr(simulation, "build_model", build_model)  # the one way a model is built, where it is used
    monkeypatch.setattr(settings_module, "build_model", build_model)
    threads = _Threads(monkeypatch)
    window.model = None  # nothing built yet: the job builds it
    models = []
    window.state.events.tongue_model.connect(lambda event: models.append(event.value))
    show_and_simulate(qtbot, window, demo_session(3.5, 5.8))
    assert built == [False]  # built once, in the job's thread
    from tonguevis.sim.placement import source_model

    # handed back and kept (the motion's own is that model placed in the speaker)
    assert window.model is models[-1] is source_model(window.session.motion.model)
    assert ("motion", True) in threads.events  # the recorder saw the motion announced (on the GUI thread)
    assert threads.off_the_gui_thread() == []

    # The Energy tab's corpus: the model it builds is handed back to the app model, the same way.
    window.model = None
    tab = EnergyTab(window.state, settings=RunSettings(modes=MODES, landmarks="rule"))
    window.register_tab("Energy", tab)
    with qtbot.waitSignal(tab.motionsLoaded, timeout=120000):
        tab.load_paths([DEMO])
    assert built == [False, False] and window.model is not None
    assert "spk1_ta" in window.state.motions
    assert threads.off_the_gui_thread() == []


def test_the_energy_tab_cancels_its_corpus(qtbot, window):
    from tests.gui.conftest import DEMO
    from tonguevis.gui.energy_tab import EnergyTab

    tab = EnergyTab(window.state, settings=RunSettings(modes=MODES, landmarks="rule"))
    window.register_tab("Energy", tab)
    tab.load_paths([DEMO])
    assert not tab.cancel_button.isHidden() and not tab.add_button.isEnabled()
    with qtbot.waitSignal(tab.job.ended, timeout=60000) as blocker:
        tab.cancel_button.click()
    assert blocker.args == ["cancelled"]
    assert "cancelled" in tab.hover_label.text() and tab.add_button.isEnabled() and tab.cancel_button.isHidden()
    assert tab.curves == [] and window.state.motions == {}


def test_the_tabs_talk_through_the_app_model(qtbot, window):
    """Simulated -> Energy curves (``motion``) -> Morph's recordings (``motions``); a frame picked in
    the Energy tab -> the morph's end (``morph_ends``); no tab holds another."""
    from tonguevis.gui.tabs import add_feature_tabs

    add_feature_tabs(window)
    energy, morph, segmentation = window.energy_tab, window.morph_tab, window.segmentation_tab
    session = show_and_simulate(qtbot, window, demo_session())
    assert segmentation.session is session  # follows the primary session
    assert {c.recording for c in energy.curves} == {"spk1_ta"}
    assert window.state.motions == {"spk1_ta": session.motion} and morph.motions == window.state.motions
    curve = energy.curves[0]
    ends = []
    window.state.events.morph_ends.connect(lambda event: ends.append((event.key, event.value, event.source)))
    for k, button in ((0, energy.to_source), (len(curve.times) // 2, energy.to_target)):
        energy.pick(curve, k)
        button.click()
    t0, t1 = float(curve.times[0]), float(curve.times[len(curve.times) // 2])
    assert ends == [("source", ("spk1_ta", t0), energy), ("target", ("spk1_ta", t1), energy)]
    assert morph.source_file.currentText() == morph.target_file.currentText() == "spk1_ta"
    assert morph.source_time.value() == pytest.approx(t0, abs=0.006)
    assert morph.target_time.value() == pytest.approx(t1, abs=0.006)
    assert morph.morph is not None  # both ends set: the morph was built
    for attribute in ("energy_tab", "morph_tab", "segmentation_tab"):  # the window's, not set from outside
        with pytest.raises(AttributeError):
            setattr(window, attribute, None)
