"""Constrained Newmark integration with warped sensor constraints."""

from __future__ import annotations

import numpy as np
import pytest

from tests.sim._models import bar_model, sensor_rows
from tonguevis.sim.constrained import point_stiffness
from tonguevis.sim.newmark import NewmarkSettings, integrate


def _raise_and_rest(amplitude, frames=260, rise=40, rate=100.0):
    """Tip target: up (and forward) over ``rise`` frames, back down, then rest."""
    t = np.arange(frames) / rate
    bump = np.zeros(frames)
    k = np.arange(2 * rise)
    bump[: 2 * rise] = amplitude * np.sin(np.pi * k / (2 * rise)) ** 2
    targets = np.zeros((frames, 1, 3))
    targets[:, 0, 2] = bump
    targets[:, 0, 0] = -0.3 * bump
    return t, targets


@pytest.fixture(scope="module")
def bar():
    model = bar_model()
    lam, phi_s, w_s = sensor_rows(model, [model.landmarks.sensors["TT"]], 20)
    return model, lam, phi_s, w_s


def _settings(model, warping):
    return NewmarkSettings(dt=0.01, alpha=model.material.alpha, beta=model.material.beta, warping=warping)


def test_linear_constraint_is_met_exactly(bar):
    model, lam, phi_s, w_s = bar
    _, targets = _raise_and_rest(0.02)
    res = integrate(lam, phi_s, w_s, targets, _settings(model, False))
    assert res.converged.all()
    np.testing.assert_allclose(np.einsum("sdm,fm->fsd", phi_s, res.q), targets, atol=1e-12)
    assert (0.5 * np.einsum("fm,m,fm->f", res.q, lam, res.q) >= 0).all()


@pytest.mark.parametrize("amplitude, rotation", [(0.01, 0.1), (0.03, 0.3), (0.05, 0.5)])
def test_warped_sensor_follows_large_raises_and_the_mesh_returns_to_rest(bar, amplitude, rotation):
    model, lam, phi_s, w_s = bar
    _, targets = _raise_and_rest(amplitude)
    res = integrate(lam, phi_s, w_s, targets, _settings(model, True))
    assert res.converged.all()
    assert np.nanmax(res.residual) < 1e-8  # metres
    assert res.iterations.mean() < 4  # Newton, not a creeping fixed point
    w = (res.q @ model.rotation_matrix(model.basis(20, cache=False)).T).reshape(len(res.q), -1, 3)
    assert np.linalg.norm(w, axis=2).max() > rotation  # the test does exercise large rotations (rad)
    disp = model.displacements(res.q[-1:], warping=True)
    assert np.abs(disp).max() < 1e-5  # 0.01 mm after the rest


def test_warped_and_linear_agree_for_tiny_motion(bar):
    model, lam, phi_s, w_s = bar
    _, targets = _raise_and_rest(1e-6)
    warped = integrate(lam, phi_s, w_s, targets, _settings(model, True))
    linear = integrate(lam, phi_s, w_s, targets, _settings(model, False))
    assert np.abs(warped.q - linear.q).max() < 1e-3 * np.abs(linear.q).max()


def test_missing_targets_let_the_model_relax(bar):
    model, lam, phi_s, w_s = bar
    _, targets = _raise_and_rest(0.02)
    targets[30:] = np.nan  # sensor lost mid-raise
    res = integrate(lam, phi_s, w_s, targets, _settings(model, True))
    assert np.isnan(res.residual[30:]).all() and np.isfinite(res.q).all()
    energy = 0.5 * np.einsum("fm,m,fm->f", res.q, lam, res.q)
    assert energy[-1] < 1e-3 * energy[29]


def test_frames_that_do_not_converge_are_flagged(bar):
    model, lam, phi_s, w_s = bar
    _, targets = _raise_and_rest(0.05, rise=5)
    settings = _settings(model, True)
    settings.max_iterations = 1
    settings.tolerance = 1e-14
    res = integrate(lam, phi_s, w_s, targets, settings)
    assert not res.converged.all()
    assert res.converged[0]  # the rest frame needs no iteration
    assert not res.recovered.any()  # unconverged but sane: the last iterate is kept, flagged


def test_a_runaway_frame_keeps_the_previous_shape_and_stops(bar, monkeypatch):
    import tonguevis.sim.newmark as newmark

    model, lam, phi_s, w_s = bar
    _, targets = _raise_and_rest(0.03)
    settings = _settings(model, True)
    free = integrate(lam, phi_s, w_s, targets, settings)
    w = np.linalg.norm(free.q @ w_s[0].T, axis=1)
    limit = 0.5 * w.max()  # frames rotating the sensor past half the peak count as runaways here
    monkeypatch.setattr(newmark, "RUNAWAY_ROTATION", limit)
    res = integrate(lam, phi_s, w_s, targets, settings)
    bad = np.flatnonzero(res.recovered)
    assert len(bad) > 0 and np.all(np.isfinite(res.q))
    assert np.all(np.linalg.norm(res.q @ w_s[0].T, axis=1) <= limit + 1e-12)  # never past the limit
    first = bad[0]
    np.testing.assert_array_equal(res.q[first], res.q[first - 1])
    assert np.all(res.qd[bad] == 0) and np.all(res.qdd[bad] == 0)


@pytest.mark.parametrize("warping", [True, False])
@pytest.mark.parametrize("compliance", ["hard", "compliant", "ramped", "runaway"])
def test_compiled_integrator_equals_the_numpy_reference(warping, compliance, monkeypatch):
    import tonguevis.sim.constrained as constrained
    import tonguevis.sim.newmark as newmark
    from tonguevis.sim.newmark_kernel import CompiledIntegrator, integrate_compiled

    if compliance == "runaway":  # a low limit, so that recoveries happen and must match
        monkeypatch.setattr(constrained, "RUNAWAY_ROTATION", 0.05)
        monkeypatch.setattr(newmark, "RUNAWAY_ROTATION", 0.05)

    model = bar_model(sensors=("TT", "TD", "TL", "TR"))
    nodes = [model.landmarks.sensors[s] for s in ("TT", "TD", "TL", "TR")]
    lam, phi_s, w_s = sensor_rows(model, nodes, 24)
    _, tip = _raise_and_rest(0.04, frames=200)
    targets = np.zeros((200, 4, 3))
    targets[:, 0] = tip[:, 0]
    targets[:, 2, 2] = 0.3 * tip[:, 0, 2]
    targets[60:70, 1] = np.nan  # a lost sensor for a while
    unit = 1.0 / point_stiffness(lam, phi_s)  # m/N
    comp = {"hard": 0.0, "runaway": 0.0, "compliant": unit / 20, "ramped": np.zeros((200, 4))}[compliance]
    if compliance == "ramped":  # sensor 2 softened over 10 frames, off for 20, back over 10
        comp[100:110, 2] = np.linspace(0.0, 5.0, 10) * unit
        comp[110:130, 2] = np.inf
        comp[130:140, 2] = np.linspace(5.0, 0.0, 10) * unit
    settings = _settings(model, warping)
    scale_q = np.abs(integrate(lam, phi_s, w_s, targets, settings).q).max()
    push = np.zeros((200, len(lam)))
    push[80:120, :3] = 0.05 * lam[:3] * scale_q  # an external modal force, as the palate's contact forces
    ref = integrate(lam, phi_s, w_s, targets, settings, compliance=comp, external=push)
    fast = integrate_compiled(lam, phi_s, w_s, targets, settings, compliance=comp, external=push)
    scale = np.abs(ref.q).max()
    assert np.abs(fast.q - ref.q).max() < 1e-10 * scale
    assert np.abs(fast.qd - ref.qd).max() < 1e-8 * np.abs(ref.qd).max()
    np.testing.assert_array_equal(fast.converged, ref.converged)
    np.testing.assert_array_equal(fast.recovered, ref.recovered)
    np.testing.assert_array_equal(fast.iterations, ref.iterations)
    np.testing.assert_allclose(fast.residual, ref.residual, atol=1e-12, equal_nan=True)
    if compliance == "compliant":  # a spring, not a rod: the sensors are followed, not held
        assert np.nanmax(ref.residual) > 1e-5
    if compliance == "runaway" and warping:
        assert ref.recovered.any()
    # Several trials in one launch give the same as one at a time.
    both = integrate_compiled(lam, phi_s, w_s, np.stack([targets, 0.5 * targets]), settings, compliance=comp,
                              external=push)
    np.testing.assert_allclose(both[0].q, fast.q, rtol=0, atol=1e-15 * scale)
    # In segments, each launch resuming from the last one's state, bit for bit the one launch; the cuts fall
    # on a sensor's loss (frame 60) and release (110), where the integrator looks at the frame before.
    integrator = CompiledIntegrator(lam, phi_s, w_s, settings, n_sensors=4)
    comp_all = np.broadcast_to(comp, (200, 4))
    cuts = [0, 1, 60, 67, 110, 111, 200]
    parts = [integrator.advance(targets[None, a:b], comp_all[None, a:b], push[None, a:b])[0]
             for a, b in zip(cuts[:-1], cuts[1:])]
    for field in ("q", "qd", "qdd", "converged", "recovered", "iterations", "residual"):
        joined = np.concatenate([getattr(part, field) for part in parts])
        np.testing.assert_array_equal(joined, getattr(fast, field), err_msg=field)
