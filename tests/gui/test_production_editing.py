"""Productions and landmarks on the sensor and sound panels; corrected by hand and saved beside the recording."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")

from tests.preprocess.test_gestures import isolated_repetitions  # noqa: E402
from tonguevis.io import write_recording  # noqa: E402
from tonguevis.io.recording import Audio, Recording  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]
STARTS = [2.5, 4.3, 6.0, 7.9]


@pytest.fixture
def recording_file(tmp_path):
    """Four isolated /ta/ (tip and a dorsum carried along) with a quiet sound track, as a file."""
    t, z, _ = isolated_repetitions(STARTS)
    zeros = np.zeros_like(t)
    sensors = {"TT": np.column_stack([zeros, zeros, z]), "TD": np.column_stack([zeros - 0.03, zeros, 0.4 * z])}
    rate = 8000.0
    sound = 0.01 * np.sin(2 * np.pi * 150 * np.arange(int(t[-1] * rate)) / rate)
    rec = Recording(100.0, t, sensors, audio=Audio(sound, rate), metadata={"file": None})
    path = tmp_path / "P01_ta.csv"
    write_recording(rec, path)
    return path


@pytest.fixture
def panels(qtbot, recording_file):
    from PySide6.QtWidgets import QVBoxLayout, QWidget

    from tonguevis.appstate import AppState
    from tonguevis.gui.audio_panel import AudioPlot
    from tonguevis.gui.sensor_panel import SensorPanel
    from tonguevis.workflows.session import load_session
    from tonguevis.gui.transport import TransportBar

    state = AppState()
    host = QWidget()
    layout = QVBoxLayout(host)
    sensors, audio, transport = SensorPanel(state), AudioPlot(state), TransportBar(state)
    for widget in (sensors, audio, transport):
        layout.addWidget(widget)
    qtbot.addWidget(host)
    host.resize(1000, 800)
    host.show()
    qtbot.waitExposed(host)
    session = load_session(recording_file)
    state.follow_session(sensors.set_session)
    state.set_session(session)
    start, end, period = session.time_range
    state.set_range(start, end, period)
    transport.set_productions(session.productions)
    audio.show_audio(session.recording.audio, (start, end), session.productions, session.recording.labels,
                     session.production_table.landmarks)
    qtbot.waitUntil(lambda: sensors.plot._drawn and audio._drawn, timeout=5000)
    yield state, session, sensors, audio, transport
    host.close()  # held until here: the panels are its children


def marker_times(ax) -> list[float]:
    """Times of the landmark markers drawn in ``ax`` (lines without a connecting line)."""
    return sorted(float(x) for line in ax.get_lines() if line.get_linestyle() == "None" for x in line.get_xdata())


def test_productions_and_landmarks_are_drawn_on_both_panels(panels):
    state, session, sensors, audio, _ = panels
    table = session.production_table
    assert len(table) == len(STARTS) and table.articulator == "TT"
    expected = sorted(t for m in table.landmarks for t in m.times.values())
    np.testing.assert_allclose(marker_times(sensors.plot.axes[2]), expected)
    np.testing.assert_allclose(marker_times(audio.wave_ax), expected)
    # on the tip's vertical trace: the closure marker sits at the trace's value there
    closure = next(line for line in sensors.plot.axes[2].get_lines() if line.get_marker() == "o")
    trace = sensors.plot.lines["TT"][2]
    np.testing.assert_allclose(closure.get_ydata(), np.interp(closure.get_xdata(), *trace.get_data()), atol=1e-9)
    assert not sensors.add_button.isEnabled() and not sensors.save_button.isEnabled()  # editing is off


def test_drag_a_boundary_add_delete_and_save(qtbot, panels, recording_file):
    from PySide6.QtCore import QPoint, Qt

    from tonguevis.workflows.session import load_session

    state, session, sensors, audio, transport = panels
    plot = sensors.plot
    original = list(session.productions)
    sensors.edit.setChecked(True)
    # drag the first production's end 0.15 s earlier with the mouse
    ax = plot.axes[1]
    y = float(np.mean(ax.get_ylim()))
    old_end = original[0][1]
    x0, py = plot.data_to_widget(ax, old_end, y)
    x1, _ = plot.data_to_widget(ax, old_end - 0.15, y)
    qtbot.mousePress(plot, Qt.MouseButton.LeftButton, pos=QPoint(x0, py))
    qtbot.mouseMove(plot, QPoint(x1, py))
    qtbot.mouseRelease(plot, Qt.MouseButton.LeftButton, pos=QPoint(x1, py))
    assert session.productions[0][1] == pytest.approx(old_end - 0.15, abs=0.02)
    assert session.productions[1:] == original[1:]
    assert transport.productions == session.productions  # every view follows the model
    assert sensors.save_button.isEnabled() and "not saved" in state.status
    # delete the third production (the cursor inside it), then add it back at its closure
    third = session.production_table[2]
    state.set_time(0.5 * (third.start + third.end))
    sensors.delete_button.click()
    assert len(session.productions) == 3
    assert len(marker_times(audio.wave_ax)) == 3 * 8
    state.set_time(third.closure)
    sensors.add_button.click()
    assert len(session.productions) == 4 and session.productions[2][0] == pytest.approx(third.start, abs=0.011)
    # a production cannot be added inside another: a dialog says why, nothing changes
    state.set_time(session.productions[1][0] + 0.05)
    sensors.add_button.click()
    assert len(session.productions) == 4 and "inside production 2" in sensors.last_dialog.text()
    sensors.last_dialog.close()
    # save: NAME.TextGrid beside the recording, read back by every command
    assert sensors.save_productions()
    assert recording_file.with_suffix(".TextGrid").is_file() and not sensors.save_button.isEnabled()
    again = load_session(recording_file)
    np.testing.assert_allclose(again.productions, session.productions, atol=1e-6)
    assert [p.label for p in again.production_table] == ["ta"] * 4


def test_a_recording_without_a_file_says_it_cannot_save(qtbot, panels):
    state, session, sensors, _, _ = panels
    session.path = None
    sensors.edit.setChecked(True)
    state.set_time(session.productions[0][0] + 0.05)
    sensors.delete_button.click()
    assert not sensors.save_productions()
    assert "no file" in sensors.last_dialog.text()

