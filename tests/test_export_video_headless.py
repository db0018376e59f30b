"""`tonguevis export-video` runs without Qt (issue 24, item 3).

The command runs in a fresh interpreter whose import system refuses PySide6, shiboken6
and pyvistaqt (and the other Qt bindings), with no X display: the video is rendered by
VTK off screen.  Before the Qt-free drawing moved to ``tonguevis.render`` the video
export imported ``gui/view3d.py`` and with it PySide6, and this run failed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from tonguevis.paths import DEMO_RECORDING

#: Top-level packages the run may not import (Qt, its bindings, and the Qt plotter).
QT_PACKAGES = ("PySide6", "shiboken6", "pyvistaqt", "PyQt5", "PyQt6", "PySide2", "qtpy")

RUNNER = textwrap.dedent("""
    import importlib.abc, json, sys

    QT = set(json.loads(sys.argv[1]))
    asked = []

    class NoQt(importlib.abc.MetaPathFinder):
        # First on the meta path: an import of a Qt package fails as if it were not installed.
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in QT:
                asked.append(name)
                raise ImportError(f"{name} is not importable in this test")
            return None

    sys.meta_path.insert(0, NoQt())
    from tonguevis.cli import main

    code = main(sys.argv[2:])
    loaded = sorted(m for m in sys.modules if m.split(".")[0] in QT)
    print("QT-REPORT " + json.dumps({"asked": sorted(set(asked)), "loaded": loaded}))
    sys.exit(code)
""")


@pytest.mark.skipif(not DEMO_RECORDING.exists(), reason="the demo recording is not shipped in data/")
def test_export_video_writes_an_mp4_without_importing_qt(tmp_path):
    from tonguevis.render.mp4 import probe_streams

    out = tmp_path / "clip.mp4"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    result = subprocess.run(
        [sys.executable, "-c", RUNNER, json.dumps(QT_PACKAGES), "export-video", str(DEMO_RECORDING),
         "--out", str(out), "--start", "5.3", "--end", "5.5", "--fps", "10", "--size", "320x240", "--quiet"],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    report = [line for line in result.stdout.splitlines() if line.startswith("QT-REPORT ")]
    assert report, result.stdout
    qt = json.loads(report[-1][len("QT-REPORT "):])
    # Nothing even tried to import Qt (a fallback behind a try/except would hide a refused import).
    assert qt == {"asked": [], "loaded": []}
    assert out.stat().st_size > 1000
    assert sorted(probe_streams(out)) == ["audio", "video"]
    # Issue 37: it said nothing of the sound it holds (only, elsewhere, when a video is silent).
    assert f"{out} (head frame, with the recording's sound: from {DEMO_RECORDING.stem}.wav)" in result.stdout
    assert [p.name for p in tmp_path.iterdir()] == ["clip.mp4"]  # no temporary file left beside it
