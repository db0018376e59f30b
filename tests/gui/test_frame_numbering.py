"""One frame numbering (issue 37, item 3): `--frame 152` showed "frame 153/1889". Frames count from 0
everywhere: the option, the transport, the views' caption, the VTK series and the XDMF export."""

from __future__ import annotations

import re

import h5py
import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import demo_session, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(180)]


def test_a_frame_is_shown_and_exported_under_the_number_it_is_asked_for(qtbot, window, tmp_path):
    from tonguevis.sim.xdmf import write_xdmf

    session = show_and_simulate(qtbot, window, demo_session())
    frames = session.frames
    n, asked = frames.n_frames, 152
    window.state.set_time(float(frames.times[asked]))  # what `tonguevis view --frame 152` does
    qtbot.waitUntil(lambda: window.view3d.frame == asked, timeout=5000)
    shown = {"transport": window.transport.label.text(),
             "caption": window.view3d.scene.time_text.GetText(2)}
    for where, text in shown.items():
        assert re.search(rf"\bframe {asked}/{n - 1}\b", text), f"the {where} says {text!r}"

    pvd = session.motion.to_vtk_series(tmp_path / "vtk", frames=[asked])
    assert f'file="frame_{asked:05d}.vtu"' in pvd.read_text()
    write_xdmf(session.motion, tmp_path / "motion.xdmf", frames=np.array([0, asked, n - 1]))
    with h5py.File(tmp_path / "motion.h5") as h5:
        assert list(h5["frames"][:]) == [0, asked, n - 1]  # the first is 0, the last n - 1, as shown
