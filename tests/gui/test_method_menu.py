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


def test_fit_the_tongue_to_the_rest_sensors_resimulates_with_the_rest_shape_fitted(qtbot, window):
    from tests.gui.conftest import demo_session, show_and_simulate

    assert not window.rest_fit_action.isChecked()
    show_and_simulate(qtbot, window, demo_session(3.5, 4.5))
    assert "rest_fit" not in window.session.motion.metadata["fit"]
    before = window.session.motion.metadata["fit"]["residual_rms_mm"]
    with qtbot.waitSignal(window.simulation_finished, timeout=120000) as blocker:
        window.rest_fit_action.setChecked(True)
    assert blocker.args == [True] and window.state.run_settings.rest_fit
    fit = window.session.motion.metadata["fit"]
    assert fit["rest_fit"]["sensors_before_rms_mm"] == pytest.approx(before) and fit["residual_rms_mm"] < 1e-9
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        window.rest_fit_action.setChecked(False)
    assert "rest_fit" not in window.session.motion.metadata["fit"]
