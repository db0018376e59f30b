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
    from tonguevis.workflows.session import load_session

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


def _screenshot_problems(rgb: np.ndarray) -> list[str]:
    """What is wrong with a (H, W, 3) window screenshot (0..1) of the demo; [] if nothing."""
    import matplotlib.colors as mcolors

    from tonguevis.render.scene import BACKGROUND, COLORMAP

    problems = []
    height, width = rgb.shape[:2]
    if width <= 800 or height <= 500:
        problems.append(f"only {width} x {height} pixels")
    # not blank: a window of plots, text and a shaded mesh has thousands of colours
    colours = len(np.unique(np.round(rgb * 255).astype(np.int64) @ [65536, 256, 1]))
    if colours <= 2000:
        problems.append(f"only {colours} distinct colours")
    # the tongue: saturated colours of the plasma map (hues from violet through red to yellow; shading
    # keeps the hue), filling most of the middle of the 3D view on the left (the colour bar alone is tiny)
    assert COLORMAP == "plasma"
    hsv = mcolors.rgb_to_hsv(rgb)
    hue = 360 * hsv[..., 0]
    tongue = (hsv[..., 1] > 0.35) & (hsv[..., 2] > 0.2) & ((hue >= 230) | (hue <= 65))
    middle = tongue[int(0.1 * height):int(0.7 * height), int(0.05 * width):int(0.4 * width)]
    if tongue.mean() <= 0.08 or middle.mean() <= 0.2:  # the camera leaves room for the colour bar (dd36ca6)
        problems.append(f"tongue colours cover {tongue.mean():.1%} of the window, {middle.mean():.1%} of the 3D view's middle")
    # VTK's frame was painted in (a failed grab leaves it black): its background shows around the tongue
    backdrop = np.linalg.norm(rgb - np.array(mcolors.to_rgb(BACKGROUND)), axis=-1) < 0.03
    if backdrop[:, : width // 2].mean() <= 0.05:
        problems.append(f"the 3D background covers {backdrop[:, : width // 2].mean():.1%} of the left half")
    return problems


def test_view_screenshot_command(tmp_path):
    if not (DEMO.exists() and _default_model_available()):
        pytest.skip("needs the demo corpus and the shipped mesh")
    import matplotlib.image as mimage

    out = tmp_path / "shot.png"
    result = _run("view", str(DEMO), "--screenshot", str(out), "--frame", "560", "--modes", "20")
    assert result.returncode == 0, result.stderr[-2000:]
    rgb = mimage.imread(out)[..., :3].astype(np.float64)  # (H, W, 3) in 0..1
    assert _screenshot_problems(rgb) == []
    # the checks can fail: a blank image, a black 3D view, the same window in greys
    assert len(_screenshot_problems(np.full_like(rgb, 0.5))) == 3
    black_view = rgb.copy()
    black_view[:, : int(0.6 * rgb.shape[1])] = 0.0
    assert len(_screenshot_problems(black_view)) == 2
    grey = np.repeat(rgb.mean(axis=2, keepdims=True), 3, axis=2)
    assert any(p.startswith("tongue colours") for p in _screenshot_problems(grey))


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
    from tonguevis.render.mp4 import probe_streams

    out = tmp_path / "demo.mp4"
    result = _run("export-video", str(DEMO), "--out", str(out), "--start", "5.5", "--end", "5.9",
                  "--modes", "20", "--size", "320x240", "--quiet")
    assert result.returncode == 0, result.stderr[-2000:]
    assert sorted(probe_streams(out)) == ["audio", "video"]


def test_view_compare_screenshot_command(tmp_path):
    """`view A --compare B --screenshot`: both simulated, B drawn in its own view beside A's."""
    other = DEMO.with_name("spk2_ta.tsv")
    if not (DEMO.exists() and other.exists() and _default_model_available()):
        pytest.skip("needs the demo corpus and the shipped mesh")
    import matplotlib.colors as mcolors
    import matplotlib.image as mimage

    from tonguevis.gui.compare import _background

    out = tmp_path / "compare.png"
    result = _run("view", str(DEMO), "--compare", str(other), "--screenshot", str(out), "--frame", "620",
                  "--modes", "20", "--color", "difference")
    assert result.returncode == 0, result.stderr[-2000:]
    rgb = mimage.imread(out)[..., :3].astype(np.float64)
    assert _screenshot_problems(rgb) == []
    # B's view (right of A's four) is painted: tongue colours, not only its flat background
    height, width = rgb.shape[:2]
    b_view = rgb[int(0.2 * height):int(0.7 * height), int(0.42 * width):int(0.66 * width)]
    backdrop = np.linalg.norm(b_view - np.array(mcolors.to_rgb(_background())), axis=-1) < 0.03
    assert 0.1 < 1 - backdrop.mean() < 0.95, f"B's view is {1 - backdrop.mean():.0%} tongue"
    bad = _run("view", str(DEMO), "--compare", str(tmp_path / "missing.tsv"), "--screenshot", str(out))
    assert bad.returncode == 2 and "missing.tsv" in bad.stderr and "Traceback" not in bad.stderr
