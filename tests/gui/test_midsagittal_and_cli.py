"""Midsagittal-only recordings (Haskins MVIEW: TT, TB, TR=back, JAW), the Qt-free core, the commands."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.conftest import REPO, shared_file  # noqa: E402
from tests.gui.conftest import DEMO, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


def test_haskins_midsagittal_recording_plays(qtbot, window):
    from tonguevis.gui.session import load_session

    path = shared_file("ema", "mview", "F01_B01_S01_R01_N.mat")
    session = load_session(path, sensor_map="haskins")
    assert not {"TL", "TR"} & set(session.recording.sensors)
    show_and_simulate(qtbot, window, session)
    motion = session.motion
    assert set(motion.sensor_names) <= {"TT", "TB", "TBK"} and "TT" in motion.sensor_names
    plotted = set(window.sensor_panel.plot.lines)
    assert {"TT", "TB", "TBK"} <= plotted and not {"TL", "TR", "JAW"} & plotted  # the jaw on request:
    window.sensor_panel.set_show_others(True)
    assert "JAW" in window.sensor_panel.plot.lines
    before = np.array(window.view3d.scene.surface.points)
    window.state.set_time(window.state.start + 1.3)
    assert np.abs(np.array(window.view3d.scene.surface.points) - before).max() > 0
    assert window.audio.cursor_time == window.state.time


def _default_model_available() -> bool:
    from tonguevis.mesh.default import default_mesh_path

    return default_mesh_path().exists()


def _run(*args, timeout=110):
    env = dict(os.environ, QT_QPA_PLATFORM=os.environ.get("QT_QPA_PLATFORM", "xcb"))
    return subprocess.run([sys.executable, "-m", "tonguevis", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO, env=env)


def test_view_screenshot_command(tmp_path):
    if not (DEMO.exists() and _default_model_available()):
        pytest.skip("needs the demo corpus and the shipped mesh")
    from PySide6.QtGui import QImage

    out = tmp_path / "shot.png"
    result = _run("view", str(DEMO), "--screenshot", str(out), "--frame", "560", "--modes", "20")
    assert result.returncode == 0, result.stderr[-2000:]
    image = QImage(str(out))
    assert image.width() > 800 and image.height() > 500


def test_view_command_reports_a_bad_file(tmp_path):
    bad = tmp_path / "bad.pos"
    bad.write_bytes(b"\x00" * 10)
    result = _run("view", str(bad), "--screenshot", str(tmp_path / "x.png"))
    assert result.returncode == 2
    assert "bad.pos" in result.stderr
    assert not (tmp_path / "x.png").exists()


def test_view_screenshot_of_unmapped_channels_is_a_one_line_error(tmp_path):
    """Headless, nobody can answer the sensor-mapping dialog: the run ends like any other command's error."""
    from tests.io.synthetic import make_recording
    from tonguevis.io import write_recording

    path = tmp_path / "unmapped.tsv"  # NDI Wave Ids 11-13 match no preset; no sensor_map.json beside it
    write_recording(make_recording(n=60, names=("S11", "S12", "S13"), audio_rate=None), path)
    result = _run("view", str(path), "--screenshot", str(tmp_path / "x.png"))
    assert result.returncode == 2, result.stderr[-2000:]
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("tonguevis view: error:")
    assert str(path) in lines[0] and "--sensors" in lines[0] and "S11" in lines[0]
    assert not (tmp_path / "x.png").exists()


def test_export_video_command(tmp_path):
    if not (DEMO.exists() and _default_model_available()):
        pytest.skip("needs the demo corpus and the shipped mesh")
    from tonguevis.gui.video import probe_streams

    out = tmp_path / "demo.mp4"
    result = _run("export-video", str(DEMO), "--out", str(out), "--start", "5.5", "--end", "5.9",
                  "--modes", "20", "--size", "320x240", "--quiet")
    assert result.returncode == 0, result.stderr[-2000:]
    assert sorted(probe_streams(out)) == ["audio", "video"]
