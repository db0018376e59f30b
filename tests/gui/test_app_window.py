"""The main window on real pieces: demo recording, real simulate(), four 3D views, plots, audio."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import demo_session, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


def cursors(window):
    return {name: view.cursor_time for name, view in window.time_views.items()}


def test_play_moves_the_tongue_and_every_cursor_together(qtbot, window):
    session = show_and_simulate(qtbot, window, demo_session())
    state = window.state
    assert session.frames.n_frames == session.motion.n_frames > 200
    state.set_time(5.2)  # just before the first syllable
    before = np.array(window.view3d.scene.surface.points)
    renders = window.view3d.renders
    import time

    started = time.perf_counter()
    state.set_playing(True)
    qtbot.waitUntil(lambda: state.time > 6.2, timeout=10000)  # a second of playback
    state.set_playing(False)
    elapsed = time.perf_counter() - started
    after = np.array(window.view3d.scene.surface.points)
    # The rendered buffer moved (in place: same dataset object as at build time).
    assert np.abs(after - before).max() > 1e-4
    assert window.view3d.renders > renders
    # Driven by a clock, not by frame counting: never ahead of real time (speed 1).
    assert state.time - 5.2 <= elapsed + 0.05
    i = session.frames.frame_at(state.time)
    # In the head frame (the default): the simulated tongue carried by the jaw's translation.
    assert np.allclose(after, session.frames.points[i] + session.motion.jaw_offset[i])
    # Every view shows the same time.
    times = cursors(window)
    assert all(t == state.time for t in times.values()), times
    assert "wall clock" in window.statusBar().currentMessage() or "audio" in window.statusBar().currentMessage()


def test_click_in_sensor_plot_seeks_every_view(qtbot, window):
    from PySide6.QtCore import QPoint, Qt

    show_and_simulate(qtbot, window, demo_session())
    plot = window.sensor_panel.plot
    ax = plot.axes[2]
    qtbot.waitUntil(lambda: plot._drawn, timeout=5000)
    x, y = plot.data_to_widget(ax, 6.0, float(np.mean(ax.get_ylim())))
    qtbot.mouseClick(plot, Qt.MouseButton.LeftButton, pos=QPoint(x, y))
    state = window.state
    assert abs(state.time - 6.0) < 0.02  # within two frames of pixel rounding
    assert all(t == state.time for t in cursors(window).values())
    # The 3D view shows the frame of that time (in the head frame: carried by the jaw's translation).
    frames = window.session.frames
    i = frames.frame_at(state.time)
    assert np.allclose(window.view3d.scene.surface.points, frames.points[i] + frames.motion.jaw_offset[i])


def test_waveform_drag_and_slider_and_steps(qtbot, window):
    from PySide6.QtCore import QPoint, Qt

    show_and_simulate(qtbot, window, demo_session())
    audio = window.audio
    qtbot.waitUntil(lambda: audio._drawn, timeout=5000)
    x0, y = audio.data_to_widget(audio.wave_ax, 4.0, 0.0)
    x1, _ = audio.data_to_widget(audio.wave_ax, 5.5, 0.0)
    qtbot.mousePress(audio, Qt.MouseButton.LeftButton, pos=QPoint(x0, y))
    qtbot.mouseMove(audio, QPoint(x1, y))
    qtbot.mouseRelease(audio, Qt.MouseButton.LeftButton, pos=QPoint(x1, y))
    assert abs(window.state.time - 5.5) < 0.02
    window.transport.slider.setValue(100)
    assert window.state.time == pytest.approx(window.state.start + 100 * window.state.frame_period)
    t = window.state.time
    window.transport.forward.click()
    assert window.state.time == pytest.approx(t + window.state.frame_period)


def test_loop_current_production(qtbot, window):
    session = show_and_simulate(qtbot, window, demo_session())
    assert session.productions, "the demo's first train has productions"
    start, end = session.productions[0]
    window.state.set_time(0.5 * (start + end))
    window.transport.loop.setChecked(True)
    assert window.state.loop == (start, end)
    window.state.set_speed(1.0)
    window.state.set_playing(True)
    # Playing past the production's end wraps to its start.
    wrapped = []
    window.state.events.time.connect(lambda e: wrapped.append(e.value))
    qtbot.waitUntil(lambda: any(b < a for a, b in zip(wrapped, wrapped[1:])), timeout=5000)
    window.state.set_playing(False)
    assert all(start <= t <= end for t in wrapped)


def test_colour_modes_change_scalars(qtbot, window):
    session = show_and_simulate(qtbot, window, demo_session())
    window.state.set_time(6.0)
    frames = session.frames
    i = frames.frame_at(6.0)
    values = window.view3d.scene.surface.point_data["value"]
    assert np.allclose(values, frames.scalars["displacement"][i])
    window.state.set_color("energy")
    assert np.allclose(window.view3d.scene.surface.point_data["value"], frames.scalars["energy"][i])
    window.state.set_color("plain")
    scene = window.view3d.scene
    assert scene.lookup_table is None and not scene.scalar_bar.GetVisibility()
    colours = scene.tongue_colours()
    assert np.allclose(colours, colours[0])  # one colour, whatever the scalars


def test_malformed_file_gives_a_dialog_and_the_app_keeps_running(qtbot, window, tmp_path):
    bad = tmp_path / "broken.tsv"
    bad.write_text("AudioTime[s]\tnot an NDI header\n1\t2\n")
    assert not window.open_recording(bad)
    box = window.last_dialog
    assert box is not None and box.isVisible()
    assert "broken.tsv" in box.text()
    box.close()
    # Still alive: a good recording opens and simulates afterwards.
    show_and_simulate(qtbot, window, demo_session(3.5, 5.8))


@pytest.mark.gui
@pytest.mark.timeout(180)
def test_a_second_recording_opens_after_the_first(qtbot, window):
    """Rebuilding the scene for a new motion must recreate its colour bar (pyvista remembers titles)."""
    show_and_simulate(qtbot, window, demo_session(3.5, 5.8))
    show_and_simulate(qtbot, window, demo_session(4.0, 6.0))
    assert window.view3d.scene.scalar_bar is not None


def test_plain_tonguevis_opens_the_ta_train_with_its_sound(qtbot, window):
    """The README's first command promises the /ta/ train: chosen by name, not the first file in data/."""
    from tonguevis.paths import DATA_DIR

    if not (DATA_DIR / "spk1_ta.tsv").exists():
        pytest.skip("demo corpus not built")
    with qtbot.waitSignal(window.simulation_finished, timeout=60000):
        window.open_demo()  # what `tonguevis` (no arguments) runs
    assert window.session.path == DATA_DIR / "spk1_ta.tsv"
    assert window.session.recording.audio is not None
    assert "spk1_ta.tsv" in window.windowTitle()


def test_unknown_channels_ask_for_a_sensor_map(qtbot, window, tmp_path):
    import shutil

    from tests.gui.conftest import DEMO

    if not DEMO.exists():
        pytest.skip("demo corpus not built")
    copy = tmp_path / "nomap.tsv"
    shutil.copy(DEMO, copy)  # no sensor_map.json beside it: channels keep their NDI names
    assert window.open_recording(copy)
    dialog = window.last_dialog
    from tonguevis.gui.dialogs import SensorMapDialog

    assert isinstance(dialog, SensorMapDialog)
    assert dialog.problem_text()  # nothing chosen yet: not acceptable
    channels = list(dialog.boxes)
    dialog.set_role(channels[1], "TT")
    dialog.set_role(channels[2], "TT")
    assert "several" in dialog.problem_text()
    dialog.set_role(channels[2], "TD")
    assert dialog.problem_text() == ""
    assert dialog.mapping() == {"TT": channels[1], "TD": channels[2]}


def test_cancel_simulation(qtbot, window):
    session = demo_session()
    with qtbot.waitSignal(window.simulation_finished, timeout=30000) as blocker:
        window.show_session(session)
        window.worker.cancel()
    assert blocker.args == [False]
    assert "cancelled" in window.statusBar().currentMessage()
    assert window.session.frames is None


def test_recent_files_remembered(qtbot, window, tmp_path):
    bad = tmp_path / "missing.tsv"
    window.open_recording(bad)  # fails: not remembered
    assert str(bad) not in window.recent_files()
    from tests.gui.conftest import DEMO

    if DEMO.exists():
        window.open_recording(DEMO)
        window.controller.stop("primary")
        assert window.recent_files()[0] == str(DEMO.resolve())
        assert window.recent_menu.actions()[0].text() == str(DEMO.resolve())


def test_half_speed_plays_at_half_speed(qtbot, window):
    import time

    show_and_simulate(qtbot, window, demo_session())
    state = window.state
    state.set_speed(0.5)
    state.set_time(5.2)
    started = time.perf_counter()
    state.set_playing(True)
    qtbot.waitUntil(lambda: state.time > 5.5, timeout=10000)
    elapsed = time.perf_counter() - started
    state.set_playing(False)
    assert state.time - 5.2 <= 0.5 * elapsed + 0.05  # recording time runs at half the wall clock
    assert elapsed >= 0.55


def test_audio_device_drives_the_clock(qtbot, window):
    from tonguevis.gui.playback import AudioClock, audio_output_available

    if not audio_output_available():
        pytest.skip("no audio output device (the wall-clock fallback is tested instead)")
    show_and_simulate(qtbot, window, demo_session())
    state = window.state
    state.set_time(5.2)
    state.set_playing(True)
    qtbot.waitUntil(lambda: state.time > 5.6, timeout=10000)
    clock = window.playback.clock
    assert isinstance(clock, AudioClock)
    assert "audio clock" in window.statusBar().currentMessage()
    # The time shown is the sink's position: consumed audio, mapped to recording time.
    position = clock._start + clock.sink.processedUSecs() * 1e-6
    assert abs(state.time - position) < 0.1
    state.set_playing(False)


def test_jaw_and_palate_shown_and_hidden(qtbot, window):
    show_and_simulate(qtbot, window, demo_session())
    scene = window.view3d.scene
    from tonguevis.render.scene import context_surfaces

    if not context_surfaces():
        pytest.skip("no jaw/palate surfaces in meshes/")
    assert scene.context_actors and all(a.GetVisibility() for a in scene.context_actors)
    window.context_action.setChecked(False)
    assert not any(a.GetVisibility() for a in scene.context_actors)


def test_stalled_audio_clock_falls_back_to_the_wall_clock(qtbot, monkeypatch):
    from PySide6.QtCore import QObject

    import tonguevis.gui.playback as playback
    from tonguevis.appstate import AppState

    class StuckAudio:
        kind = "audio"

        def start(self, t0, t1, speed):
            self.t0 = t0

        def time(self):
            return self.t0  # a device that never consumes a sample

        def exhausted(self):
            return False

        def stop(self):
            pass

    monkeypatch.setattr(playback, "STARTUP_S", 0.2)
    parent = QObject()
    state = AppState(0.0, 10.0, 0.01)
    controller = playback.PlaybackController(state, parent)
    monkeypatch.setattr(controller, "_make_clock", lambda: (StuckAudio(), "playing with sound (audio clock)"))
    messages = []
    controller.status.connect(messages.append)
    state.set_time(1.0)
    state.set_playing(True)
    qtbot.waitUntil(lambda: state.time > 1.2, timeout=5000)
    state.set_playing(False)
    assert isinstance(controller.clock, playback.WallClock)
    assert any("stalled" in m for m in messages)
    controller.shutdown()


def test_feature_tabs_join_the_window_and_get_the_apps_motion(qtbot, window):
    from tonguevis.gui.tabs import add_feature_tabs

    add_feature_tabs(window)
    titles = [window.tabs.tabText(i) for i in range(window.tabs.count())]
    assert titles[:2] == ["Sensors", "Modal q(t)"] and {"Energy", "Morph"} <= set(titles)
    session = show_and_simulate(qtbot, window, demo_session())
    assert session.productions
    # The Energy tab got the curves of the productions this window simulated.
    curves = window.energy_tab.curves
    assert curves and {c.recording for c in curves} == {"spk1_ta"}
    assert "spk1_ta" in window.morph_tab.motions


def test_drop_a_file_and_open_a_mesh(qtbot, window, tmp_path):
    from PySide6.QtCore import QMimeData, QPointF, Qt, QUrl
    from PySide6.QtGui import QDropEvent

    bad = tmp_path / "dropped.tsv"
    bad.write_text("not a recording\n")
    mime = QMimeData()
    mime.setUrls([QUrl.fromLocalFile(str(bad))])
    event = QDropEvent(QPointF(10, 10), Qt.DropAction.CopyAction, mime, Qt.MouseButton.LeftButton,
                       Qt.KeyboardModifier.NoModifier)
    window.dropEvent(event)
    assert "dropped.tsv" in window.last_dialog.text()
    window.last_dialog.close()
    # A mesh (by extension) replaces the model; a broken one gives a dialog naming it.
    broken = tmp_path / "broken.vtu"
    broken.write_text("<VTKFile>")
    model = window.model
    window.open_path(broken)
    assert window.model is model and "broken.vtu" in window.last_dialog.text()
    window.last_dialog.close()
    from tonguevis.paths import MESH_DIR

    shipped = MESH_DIR / "tongue.vtu"
    if not shipped.exists():
        pytest.skip("meshes/tongue.vtu not built")
    window.open_path(shipped)
    assert window.model is not model and window.model.mesh.n_nodes > 1000


def test_the_status_bar_says_how_believable_the_motion_is(qtbot, window):
    """Issue 11: amplification, volume change and sensor misfit of every run, in the status bar."""
    show_and_simulate(qtbot, window, demo_session(3.5, 5.8))
    message = window.statusBar().currentMessage()
    p = window.session.motion.metadata["plausibility"]
    assert "far-field amplification" in message and "sensor misfit" in message
    assert f"{p['amplification']:.2f}" in message and f"{p['volume_change_max_percent']:.2f} %" in message
    assert window.statusBar().toolTip() == message  # whole there: the notes run past the bar's width


def test_a_tongue_placed_at_the_adult_size_says_so_in_the_status(qtbot, window):
    """The demo's sensors laid out 2.3 times wider apart, their motion unchanged (a tongue 12 times the
    block's by the alignment): simulated at the generic size, and the status (and its tooltip) says why."""
    from dataclasses import replace

    import numpy as np

    from tonguevis.workflows.session import make_session

    session = demo_session(3.5, 5.8)
    tongue = {k: v for k, v in session.recording.sensors.items() if k in ("TT", "TB", "TD", "TL", "TR")}
    means = {k: np.nanmean(v, axis=0) for k, v in tongue.items()}
    centre = np.mean(list(means.values()), axis=0)
    spread = {k: v + 1.3 * (means[k] - centre) for k, v in tongue.items()}
    wide = replace(session.recording, sensors={**session.recording.sensors, **spread})
    show_and_simulate(qtbot, window, make_session(wide, session.path))
    assert window.session.motion.metadata["fit"]["size_from"] == "adult norm"
    assert "tongue at the generic adult size" in window.statusBar().toolTip()


def test_the_window_fits_a_laptop_screen_with_every_tab(qtbot, window):
    """With a recording open and every feature tab, the window can be made 1366 px wide (a common
    laptop screen): the views' combo boxes are narrower than their longest entries (shown whole
    in their lists), and the model's description is cut rather than widening the window."""
    from tonguevis.gui.tabs import add_feature_tabs

    add_feature_tabs(window)
    show_and_simulate(qtbot, window, demo_session())
    qtbot.wait(100)
    for combo in (window.view3d.colour, window.view3d.reference):
        longest = max(combo.fontMetrics().horizontalAdvance(combo.itemText(k)) for k in range(combo.count()))
        assert combo.minimumSizeHint().width() < longest, combo.currentText()
        combo.showPopup()  # the list shows the entries whole
        qtbot.wait(50)
        assert combo.view().window().width() >= longest
        combo.hidePopup()
    message = window.view3d.message
    assert message.text() and message.minimumSizeHint().width() < message.fontMetrics().horizontalAdvance(message.text())
    assert window.minimumSizeHint().width() <= 1366, window.minimumSizeHint()
    window.resize(1366, 768)
    qtbot.wait(100)
    assert window.width() <= 1366
