"""Simulation ▸ Method: the app simulates with warping, the linear modes or seed 001's quadratic domains."""

from __future__ import annotations

import pytest

pytestmark = [pytest.mark.gui, pytest.mark.timeout(240)]


def test_the_method_menu_resimulates_with_the_chosen_method(qtbot, window):
    from tests.gui.conftest import demo_session, show_and_simulate

    assert window.method_actions["warped"].isChecked()
    show_and_simulate(qtbot, window, demo_session(3.5, 4.5))
    assert window.session.motion.warping
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        window.method_actions["linear"].trigger()
    assert window.state.run_settings.method == "linear" and not window.session.motion.warping
    with qtbot.waitSignal(window.simulation_finished, timeout=200000):
        window.method_actions["domains"].trigger()
    assert window.session.motion.metadata["method"] == "domains"
    assert window.method_actions["domains"].isChecked() and not window.method_actions["linear"].isChecked()
