"""The Morph tab: ends from recordings and times, slider shows the blend in place, play goes there and back."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.analysis.energy_support import MODES, box_tongue  # noqa: E402
from tonguevis.sim.motion import Motion  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


def _q(seed, scale=4e-3):
    rng = np.random.default_rng(seed)
    return rng.normal(size=MODES) * scale / (1 + np.arange(MODES))


def _motion(model, qs, t0):
    f = len(qs)
    q = np.asarray(qs)
    return Motion(times=t0 + 0.01 * np.arange(f), q=q, model=model, warping=True, sensor_names=[],
                  sensor_nodes=np.zeros(0, int), targets=np.zeros((f, 0, 3)), sensor_residual=np.zeros((f, 0)),
                  energy=model.energy(q), volume_change=np.zeros(f), converged=np.ones(f, bool))


@pytest.fixture
def tab(qtbot):
    from tonguevis.gui.morph_tab import MorphTab

    model = box_tongue()
    motions = {"spk1_la": _motion(model, [_q(1) * k / 4 for k in range(5)], 5.0),
               "spk1_ka": _motion(model, [_q(2) * k / 4 for k in range(5)], 8.0)}
    widget = MorphTab()
    qtbot.addWidget(widget)
    widget.resize(1000, 700)
    widget.set_motions(motions)
    widget.show()
    qtbot.waitExposed(widget)
    yield widget
    widget.timer.stop()
    widget.plotter.close()


def test_ends_slider_and_colours(tab, tmp_path):
    tab.set_end("source", "spk1_la", 5.04, build=False)
    tab.set_end("target", "spk1_ka", 8.02)
    morph = tab.morph
    assert morph is not None
    np.testing.assert_allclose(morph.q_source, _q(1))
    np.testing.assert_allclose(morph.q_target, 0.5 * _q(2))
    ids = tab.surface_node_ids
    model = box_tongue()
    # t = 0 shows the source.
    np.testing.assert_allclose(tab.displayed_points(), (model.mesh.points + model.displacement(_q(1)))[ids], atol=1e-6)
    # The slider is the blend: at its end the target is shown.
    tab.slider.setValue(tab.slider.maximum())
    assert tab.t == 1.0
    np.testing.assert_allclose(tab.displayed_points(),
                               (model.mesh.points + model.displacement(0.5 * _q(2)))[ids], atol=1e-6)
    tab.slider.setValue(tab.slider.maximum() // 4)
    np.testing.assert_allclose(tab.displayed_points(), morph.points(0.25)[ids], atol=1e-6)
    assert "t = 0.25" in tab.blend_label.text() and "source spk1_la @ 5.04 s" in tab.blend_label.text()
    # Colours: the CDF of eq. (14), one value per surface face, spread over (0, 1).
    colours = np.asarray(tab.surface.cell_data["difference"])
    assert colours.min() < 0.1 and colours.max() > 0.9
    assert "percentile" in tab.legend_label.text() and "1/m" in tab.legend_label.text()
    eq14_colours = colours.copy()
    # Colouring by the size-independent node mean re-ranks the elements and changes the legend's unit.
    tab.difference.setCurrentIndex(1)
    assert tab.morph.difference == "node_mean" and "m²" in tab.legend_label.text()
    assert not np.allclose(np.asarray(tab.surface.cell_data["difference"]), eq14_colours)
    tab.grab().save(str(tmp_path / "morph_tab.png"))


def test_play_goes_forward_and_back(tab, qtbot):
    tab.set_end("source", "spk1_la", 5.04, build=False)
    tab.set_end("target", "spk1_ka", 8.04)
    seen = []
    tab.blendChanged.connect(seen.append)
    tab.set_playing(True)
    assert tab.timer.isActive() and tab.play_button.text() == "Pause"
    for _ in range(70):
        tab._tick()
    tab.play_button.click()
    assert not tab.timer.isActive()
    assert max(seen) == 1.0
    peak = seen.index(1.0)
    assert np.all(np.diff(seen[: peak + 1]) > 0) and np.all(np.diff(seen[peak:]) < 0)


def test_morph_of_unknown_recording_says_so(tab):
    tab.set_end("source", "spk9_xx", 1.0)
    assert "not been simulated" in tab.status.text()
    assert tab.morph is None
