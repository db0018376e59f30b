"""Simulation ▸ Method: the app simulates with warping, the linear modes or the quadratic domains (Luo et al. 2017)."""

from __future__ import annotations

from tonguevis.sim.settings import RunSettings

import pytest

from tests.test_cli_help import help_of

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
        window.rest_fit_action.trigger()
    assert blocker.args == [True] and window.state.run_settings.rest_fit
    fit = window.session.motion.metadata["fit"]
    assert fit["rest_fit"]["sensors_before_rms_mm"] == pytest.approx(before) and fit["residual_rms_mm"] < 1e-9
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        window.rest_fit_action.trigger()
    assert "rest_fit" not in window.session.motion.metadata["fit"]


def test_the_tongue_size_menu_resimulates_at_the_chosen_size(qtbot, window):
    from tests.gui.conftest import demo_session, show_and_simulate

    assert window.size_actions["adult"].isChecked() and window.state.run_settings.tongue_size == "adult"
    show_and_simulate(qtbot, window, demo_session(3.5, 4.5))
    assert window.session.motion.metadata["fit"]["size_from"] in ("alignment", "adult norm")
    with qtbot.waitSignal(window.simulation_finished, timeout=120000) as blocker:
        window.size_actions["generic"].trigger()
    assert blocker.args == [True] and window.state.run_settings.tongue_size == 1.0
    fit = window.session.motion.metadata["fit"]
    assert fit["size_from"] == "given" and fit["fitted_to"] == "upper surface" and fit["tongue_size"] == 1.0
    assert window.session.motion.model.rest_volume == pytest.approx(window.model.rest_volume, rel=1e-9)
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        window.size_actions["alignment"].trigger()
    assert window.state.run_settings.tongue_size is None
    assert window.session.motion.metadata["fit"]["fitted_to"] == "rule nodes"
    assert window.size_actions["alignment"].isChecked() and not window.size_actions["generic"].isChecked()


def test_the_app_opens_at_the_size_the_command_line_gives(qtbot, settings):
    """``tonguevis view --tongue-size 1``: the run settings and the Tongue size menu say so before anything runs."""
    from tonguevis.gui.app import create_window

    window = create_window(settings=RunSettings(modes=20, tongue_size=1.0), preferences=settings, feature_tabs=False)
    qtbot.addWidget(window)
    assert window.state.run_settings.tongue_size == 1.0 and window.size_actions["generic"].isChecked()
    qtbot.waitUntil(lambda: window.session is not None and window.session.motion is not None, timeout=120000)
    assert window.session.motion.metadata["fit"]["tongue_size"] == 1.0
    window.close()


def test_the_app_follows_its_model_whoever_changes_the_settings(qtbot, window):
    """Issue 34: a run setting changed by a script (not a menu) re-simulates the open recording through the
    controller, and the menus' check marks follow the same event (no check mark set by hand)."""
    from tests.gui.conftest import demo_session, show_and_simulate

    show_and_simulate(qtbot, window, demo_session(3.5, 4.5))
    first = window.session.motion
    assert window.patches_action.isChecked() and not window.rest_fit_action.isChecked()
    with qtbot.waitSignal(window.simulation_finished, timeout=120000) as blocker:
        window.state.change_run_settings(None, sensor_patches=None, method="linear", tongue_size=1.0)
    assert blocker.args == [True] and window.session.motion is not first
    assert not window.session.motion.warping and "sensor_patches" not in window.session.motion.metadata
    assert not window.patches_action.isChecked() and window.method_actions["linear"].isChecked()
    assert window.size_actions["generic"].isChecked() and not window.size_actions["adult"].isChecked()
    assert not window.controller.jobs["primary"].isRunning()  # done, nothing left running


def test_a_palate_tried_becomes_the_apps_only_when_it_simulates(qtbot, window):
    """File ▸ Load palate: the controller simulates against it and writes it to the model once that succeeded,
    without a second simulation."""
    from tests.gui.conftest import demo_session, show_and_simulate

    show_and_simulate(qtbot, window, demo_session(3.5, 4.5))
    started = []
    original = window.controller.simulate
    window.controller.simulate = lambda *a, **kw: started.append(a) or original(*a, **kw)
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        window.use_generic_palate()
    assert window.palate == "generic" and window.session.motion.penetration is not None
    qtbot.wait(300)
    assert len(started) == 1  # the settings event the controller wrote itself did not simulate again


def test_press_the_closures_follows_the_settings_and_resimulates(qtbot, window, tmp_path):
    """Simulation ▸ Press the closures (issue 36): checked by default (the run settings' closures), unticking it
    re-simulates against the palate without the tip pressed at the closures (as --no-closures), and a script's
    change ticks it back."""
    from tests.gui.conftest import demo_session, show_and_simulate

    window.state.set_run_settings(window.state.run_settings.replace(frame="model"))
    assert window.closures_action.isChecked() and window.state.run_settings.closures
    from tests.gui.test_palate_contact import flat_palate

    path = tmp_path / "roof.stl"
    flat_palate().save(path)
    show_and_simulate(qtbot, window, demo_session(3.5, 6.8))
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        assert window.load_palate(path)
    first = window.session.motion
    pressed = first.metadata["contact"]
    with qtbot.waitSignal(window.simulation_finished, timeout=120000) as blocker:
        window.closures_action.trigger()
    assert blocker.args == [True] and not window.state.run_settings.closures and window.session.motion is not first
    assert not window.closures_action.isChecked() and "closures" not in window.session.motion.metadata["contact"]
    assert "closures" in pressed or "closures_dropped" in pressed  # the first run pressed them (or said why not)
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        window.state.change_run_settings(None, closures=True)
    assert window.closures_action.isChecked()


def test_the_humps_follow_the_settings_and_resimulate(qtbot, window):
    """Simulation ▸ Move the tissue around each sensor as a hump (issue 36): it shows the run settings' humps,
    unticking it re-simulates with the local shapes alone (no hump columns in the motion), a script's change
    ticks it back, and without sensor patches it is greyed out."""
    from tests.gui.conftest import demo_session, show_and_simulate

    window.state.set_run_settings(window.state.run_settings.replace(frame="model", humps=True))
    assert window.humps_action.isChecked() and window.state.run_settings.humps
    show_and_simulate(qtbot, window, demo_session(3.5, 6.8))
    first = window.session.motion
    assert first.metadata["sensor_patches"]["hump_mm"] is not None
    with qtbot.waitSignal(window.simulation_finished, timeout=120000) as blocker:
        window.humps_action.trigger()
    assert blocker.args == [True] and not window.state.run_settings.humps and window.session.motion is not first
    assert not window.humps_action.isChecked() and window.session.motion.metadata["sensor_patches"]["hump_mm"] is None
    assert window.session.motion.q.shape[1] < first.q.shape[1]
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        window.state.change_run_settings(None, humps=True)
    assert window.humps_action.isChecked()
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        window.state.change_run_settings(None, sensor_patches=None)
    assert not window.humps_action.isEnabled()


def test_the_methods_are_said_in_a_users_words_with_their_speed(window):
    """Issue 37: the menu said "seed 001" (the project's name for a paper) and, like `--method`'s help,
    "tens of frames per second" for a method that runs a few hundred (scripts/bench_domains.py: 300-500
    frames/s whole trial on 2 cores, the modal methods 6,000-24,000)."""
    texts = [(a.text(), a.toolTip()) for a in window.method_actions.values()]
    assert not any("seed" in text.lower() or "seed" in tip.lower() for text, tip in texts), texts
    domains = window.method_actions["domains"]
    for said in (domains.toolTip(), help_of("simulate", "--method")):  # the same words
        assert "a few hundred frames/s" in said and "the modal methods thousands" in said, said
        assert "Luo et al. 2017" in said and "tens of" not in said
    assert "nonlinear" in domains.text().lower()
