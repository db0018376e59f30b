"""The Modal tab draws without matplotlib's layout warnings (issue 27, item 5)."""

from __future__ import annotations

import warnings
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("PySide6")

from tonguevis.appstate import AppState  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


def _session(seconds: float, modes: int = 30):
    times = np.arange(0.0, seconds, 0.01)
    q = 1e-4 * np.sin(np.outer(times, np.arange(1, modes + 1)))
    return SimpleNamespace(motion=SimpleNamespace(times=times, q=q))


def test_the_modal_surface_is_drawn_again_without_a_collapsed_layout(qtbot):
    """Every GUI run printed "constrained_layout not applied because axes sizes collapsed to zero": the
    3D surface, drawn once (empty, or for the previous recording), then cleared and drawn with new data."""
    from tonguevis.gui.modal_tab import ModalTab

    tab = ModalTab(AppState(0.0, 20.0, 0.01))
    qtbot.addWidget(tab)
    tab.resize(900, 600)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tab.surface_canvas.draw()  # the empty axes, as at start-up
        for seconds in (22.0, 6.0):  # a recording, then another
            tab.set_session(_session(seconds))
            tab.surface_canvas.draw()
            tab.map.draw()
    assert not [w for w in caught if "layout" in str(w.message)], [str(w.message) for w in caught]
    assert tab.ax3d.get_title().startswith("modal displacement q(t)")
