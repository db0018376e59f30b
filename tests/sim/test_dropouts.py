"""Compliant target projection and sensor dropouts: bridged, released, re-engaged without an impulse."""

from __future__ import annotations

import numpy as np
import pytest

from tests.sim._models import bar_model, sensor_rows
from tonguevis.analysis.quasistatic import linear_static
from tonguevis.sim.constrained import compliant_targets, point_stiffness
from tonguevis.sim.dropouts import bridge_short_gaps, engagement, spring_compliance


def test_compliant_targets_are_the_compliant_static_solution():
    rng = np.random.default_rng(0)
    lam = np.sort(rng.uniform(1, 10, 12))
    phi = rng.normal(size=(3, 3, 12))
    c = rng.normal(size=(5, 3, 3))
    comp = np.full((5, 3), 0.3)
    q = linear_static(lam, phi, c, compliance=0.3)
    np.testing.assert_allclose(compliant_targets(lam, phi, c, comp), np.einsum("scm,fm->fsc", phi, q), atol=1e-12)
    # A sensor that does not act (infinite compliance or NaN target) is left out of the fit ...
    comp[:, 1] = np.inf
    q2 = linear_static(lam, phi[[0, 2]], c[:, [0, 2]], compliance=0.3)
    np.testing.assert_allclose(compliant_targets(lam, phi, c, comp), np.einsum("scm,fm->fsc", phi, q2), atol=1e-12)
    c_nan = c.copy()
    c_nan[:, 1] = np.nan
    np.testing.assert_allclose(compliant_targets(lam, phi, c_nan, np.full((5, 3), 0.3)),
                               np.einsum("scm,fm->fsc", phi, q2), atol=1e-12)
    # ... and hard sensors keep their targets exactly.
    np.testing.assert_allclose(compliant_targets(lam, phi, c, np.zeros((5, 3))), c, atol=1e-12)


def test_short_gaps_are_bridged_long_ones_and_edges_are_not():
    t = np.arange(100) / 100.0
    x = np.stack([np.sin(2 * np.pi * t), np.cos(2 * np.pi * t), t], axis=1)[:, None, :].repeat(2, axis=1)
    holes = x.copy()
    holes[20:25, 0] = np.nan  # 50 ms: bridged
    holes[50:70, 0] = np.nan  # 200 ms: released
    holes[:3, 1] = np.nan  # at the start: nothing to bridge from
    out, count = bridge_short_gaps(holes, rate=100.0)
    assert count == 1
    np.testing.assert_allclose(out[20:25, 0], x[20:25, 0], atol=1e-2)  # PCHIP: within 1 % of a smooth swing
    assert np.isnan(out[50:70, 0]).all() and np.isnan(out[:3, 1]).all()


def test_a_lost_sensors_spring_weakens_and_grows_back():
    valid = np.ones((60, 1), dtype=bool)
    valid[20:40] = False
    weight, source = engagement(valid, rate=100.0, ramp_s=0.05)  # 5-frame ramps
    w = weight[:, 0]
    assert np.all(w[:20] == 1) and np.all(w[25:40] == 0) and np.all(w[45:] == 1)
    assert np.all(np.diff(w[19:26]) < 0) and np.all(np.diff(w[39:45]) > 0) and 0 < w[40] < w[44] < 1
    assert np.all(source[20:25, 0] == 19) and np.all(source[40:, 0] == np.arange(40, 60))  # anchored at the last
    comp = spring_compliance(weight, base=0.0, ramp_stiffness=10.0)
    assert np.all(comp[:20] == 0) and np.isinf(comp[25:40]).all()
    assert np.all(np.diff(comp[19:25, 0]) > 0) and np.all(np.diff(comp[40:46, 0]) < 0)


def test_a_sensor_coming_back_moves_from_the_prediction_onto_its_measurement():
    """The first frame back, the returning sensor's target sits near where the others put its node."""
    from tonguevis.sim.simulate import drive_schedule

    model = bar_model(sensors=("TT", "TD", "TL", "TR"))
    nodes = [model.landmarks.sensors[s] for s in ("TT", "TD", "TL", "TR")]
    lam, phi_s, _ = sensor_rows(model, nodes, 24)
    t = np.arange(300) / 100.0
    disp = np.zeros((300, 4, 3))
    disp[:, 0, 2] = 0.01 * np.sin(np.pi * t) ** 2
    disp[:, 2, 2] = 0.004 * np.sin(np.pi * t) ** 2  # TL: not where the others would put it
    lost = disp.copy()
    lost[100:180, 2] = np.nan  # back at 1.8 s, mid-motion
    targets, _, _ = drive_schedule(lost, 100.0, lam, phi_s, 20.0)
    springs = np.full((300, 4), 1.0 / (20.0 * point_stiffness(lam, phi_s)))
    measured = compliant_targets(lam, phi_s, disp, springs)[180:191, 2]
    springs[:, 2] = np.inf
    predicted = compliant_targets(lam, phi_s, disp, springs)[180:191, 2]
    assert np.linalg.norm(predicted[0] - measured[0]) > 1e-4  # a difference worth ramping over
    # Back over 0.1 s: from (near) the prediction to the measurement, monotonically closer to it.
    off = np.linalg.norm(targets[180:191, 2] - measured, axis=1)
    assert off[0] > 0.5 * np.linalg.norm(predicted[0] - measured[0]) and off[-1] < 1e-12
    assert np.all(np.diff(off) < 1e-12)
    # Lost: from the measurement to the prediction, and the others' targets move smoothly (no step).
    step = np.abs(np.diff(targets[95:115, [0, 1, 3]], axis=0)).max()
    assert step < 3 * np.abs(np.diff(targets[80:95, [0, 1, 3]], axis=0)).max() + 1e-6


@pytest.fixture(scope="module")
def bar():
    model = bar_model(sensors=("TT", "TD", "TL", "TR"))
    nodes = [model.landmarks.sensors[s] for s in ("TT", "TD", "TL", "TR")]
    lam, phi_s, w_s = sensor_rows(model, nodes, 24)
    return model, lam, phi_s, w_s


@pytest.mark.parametrize("stiffness", [None, 20.0])
def test_a_long_dropout_is_handed_over_without_an_impulse(bar, stiffness):
    """A sensor lost for 1 s mid-motion: the tongue goes on as the other sensors say, no kick."""
    from tonguevis.sim.newmark import NewmarkSettings, integrate
    from tonguevis.sim.simulate import drive_schedule

    model, lam, phi_s, w_s = bar
    t = np.arange(300) / 100.0
    disp = np.zeros((300, 4, 3))
    disp[:, 0, 2] = 0.01 * np.sin(np.pi * t) ** 2  # the tip rises and falls
    disp[:, 2, 2] = 0.004 * np.sin(np.pi * t) ** 2
    lost = disp.copy()
    lost[100:200, 2] = np.nan
    settings = NewmarkSettings(dt=0.01, alpha=model.material.alpha, beta=model.material.beta, warping=True)
    runs = {}
    for name, d in (("full", disp), ("lost", lost)):
        targets, comp, info = drive_schedule(d, 100.0, lam, phi_s, stiffness)
        runs[name] = integrate(lam, phi_s, w_s, targets, settings, compliance=comp)
    assert info["released"][:, 2].sum() == 100 and not runs["lost"].recovered.any()
    energy = {k: 0.5 * np.einsum("fm,m,fm->f", r.q, lam, r.q) for k, r in runs.items()}
    assert energy["lost"].max() < 1.2 * energy["full"].max()
    # The shape changes as smoothly as in the full run: no frame-to-frame kick in q.
    kick = {k: np.abs(np.diff(r.q, 2, axis=0)).max() for k, r in runs.items()}
    assert kick["lost"] < 3 * kick["full"]


def test_point_stiffness_is_the_static_stiffness_at_the_sensor_nodes(bar):
    model, lam, phi_s, _ = bar
    k = point_stiffness(lam, phi_s)
    compliance = np.einsum("scm,m,scm->sc", phi_s, 1 / lam, phi_s)  # node displacement per newton, per axis
    assert k == pytest.approx(1.0 / compliance.mean())
