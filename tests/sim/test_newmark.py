"""Constrained Newmark integration with warped sensor constraints."""

from __future__ import annotations

import numpy as np
import pytest

from tests.sim._models import bar_model, sensor_rows
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


@pytest.mark.parametrize("warping", [True, False])
def test_compiled_integrator_equals_the_numpy_reference(warping):
    from tonguevis.sim.newmark_warp import integrate_warp

    model = bar_model(sensors=("TT", "TD", "TL", "TR"))
    nodes = [model.landmarks.sensors[s] for s in ("TT", "TD", "TL", "TR")]
    lam, phi_s, w_s = sensor_rows(model, nodes, 24)
    _, tip = _raise_and_rest(0.04, frames=200)
    targets = np.zeros((200, 4, 3))
    targets[:, 0] = tip[:, 0]
    targets[:, 2, 2] = 0.3 * tip[:, 0, 2]
    targets[60:70, 1] = np.nan  # a lost sensor for a while
    settings = _settings(model, warping)
    ref = integrate(lam, phi_s, w_s, targets, settings)
    fast = integrate_warp(lam, phi_s, w_s, targets, settings)
    scale = np.abs(ref.q).max()
    assert np.abs(fast.q - ref.q).max() < 1e-10 * scale
    assert np.abs(fast.qd - ref.qd).max() < 1e-8 * np.abs(ref.qd).max()
    np.testing.assert_array_equal(fast.converged, ref.converged)
    np.testing.assert_array_equal(fast.iterations, ref.iterations)
    np.testing.assert_allclose(fast.residual, ref.residual, atol=1e-12, equal_nan=True)
    # Several trials in one launch give the same as one at a time.
    both = integrate_warp(lam, phi_s, w_s, np.stack([targets, 0.5 * targets]), settings)
    np.testing.assert_allclose(both[0].q, fast.q, rtol=0, atol=1e-15 * scale)
