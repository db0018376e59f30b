"""Fixtures of the GUI tests: a small real tongue model, a short cut of a demo recording, a window.

The model is a real :class:`TongueModel` (real assembly, modal basis and
simulate()) on a coarse block mesh, so a test simulates a few seconds of the
demo in about a second; 20 modes keep it quick.
"""

from __future__ import annotations

from tonguevis.sim.settings import RunSettings

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from tonguevis.paths import DATA_DIR

MODES = 20
DEMO = DATA_DIR / "spk1_ta.tsv"


def block_model():
    from tonguevis.mesh.structured import box_mesh
    from tonguevis.sim import TongueModel

    # A tongue-sized block (x anterior 70 mm, width 40 mm, height 40 mm), tip at x = 0.
    mesh = box_mesh(7, 4, 4, size=(0.07, 0.04, 0.04), origin=(-0.07, -0.02, -0.04))
    p = mesh.points

    def node(x, y, z):
        return int(np.argmin(np.linalg.norm(p - [x, y, z], axis=1)))

    anchors = [node(-0.07, y, -0.04) for y in (-0.02, 0.0, 0.02)] + [node(-0.03, y, -0.04) for y in (-0.01, 0.01)]
    sensors = {"TT": node(-0.01, 0, 0), "TB": node(-0.02, 0, 0), "TD": node(-0.03, 0, 0),
               "TBK": node(-0.05, 0, 0), "TL": node(-0.02, 0.01, 0), "TR": node(-0.02, -0.01, 0)}
    return TongueModel(mesh, SimpleNamespace(anchors=np.array(anchors), sensors=sensors))


def crop(recording, start: float, end: float):
    """The part of ``recording`` from ``start`` to ``end`` seconds (audio too)."""
    keep = (recording.times >= start) & (recording.times <= end)
    audio = recording.audio
    if audio is not None:
        a, b = (int(max(0, round((t - audio.offset) * audio.rate))) for t in (start, end))
        audio = replace(audio, samples=audio.samples[a:b], offset=audio.offset + a / audio.rate)
    return replace(recording, times=recording.times[keep],
                   sensors={n: v[keep] for n, v in recording.sensors.items()},
                   orientations={n: v[keep] for n, v in recording.orientations.items()}, audio=audio)


#: References to None handed back after each test (see ``_repay_none_references``).
_NONE_REFERENCES: list = []


@pytest.fixture(autouse=True)
def _repay_none_references():
    """Work around a PySide6 6.12 bug: every ``processEvents()``/``QTest.qWait()`` call from
    Python drops one reference to ``None`` (checked: 1000 calls, refcount -1000).  pytest-qt
    waits with them, so a long GUI session would drive None's refcount to zero and abort the
    interpreter ("none_dealloc").  Each test's loss is given back here."""
    import sys

    before = sys.getrefcount(None)
    yield
    lost = before - sys.getrefcount(None)
    if lost > 0:
        _NONE_REFERENCES.extend([None] * lost)


@pytest.fixture(scope="session")
def model():
    return block_model()


def demo_session(start: float = 3.5, end: float = 6.8):
    """spk1 /ta/ from 3.5 s to 6.8 s: 1.5 s of rest and the first train."""
    from tonguevis.workflows.session import load_session, make_session

    if not DEMO.exists():
        pytest.skip(f"demo corpus not built: {DEMO}")
    full = load_session(DEMO)
    return make_session(crop(full.recording, start, end), DEMO)


@pytest.fixture
def settings(tmp_path):
    from PySide6.QtCore import QSettings

    return QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)


@pytest.fixture
def window(qtbot, settings, model):
    from tonguevis.gui.window import MainWindow

    win = MainWindow(preferences=settings, run_settings=RunSettings(modes=MODES))
    win.model = model
    win.landmarks = "rule"  # the block's own sensor nodes
    qtbot.addWidget(win)
    win.resize(1400, 900)
    win.show()
    qtbot.waitExposed(win)
    yield win
    win.close()


def show_and_simulate(qtbot, window, session, timeout=60000):
    with qtbot.waitSignal(window.simulation_finished, timeout=timeout) as blocker:
        window.show_session(session)
    assert blocker.args == [True], window.statusBar().currentMessage()
    return session


def near(a: float, b: float, tol: float = 1e-9) -> bool:
    return abs(a - b) <= tol


__all__ = ["MODES", "DEMO", "block_model", "crop", "demo_session", "show_and_simulate", "near", "Path"]
