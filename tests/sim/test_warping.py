"""Accumulated rotation, its Jacobian, the warp-lang kernel, and what warping buys."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tonguevis.mesh.structured import box_mesh
from tests.sim._models import bar_model as _bar_model
from tonguevis.sim.rotation import accumulated_rotation_matrix, rotate_accumulated, rotate_accumulated_jacobian
from tonguevis.sim.kernels import rotate_accumulated_compiled


def _path_integral(w, samples=4001):
    """∫₀¹ R(s w) ds by Simpson's rule on exact rotations (an independent reference)."""
    s = np.linspace(0.0, 1.0, samples)
    mats = Rotation.from_rotvec(np.outer(s, w)).as_matrix()
    weights = np.ones(samples)
    weights[1:-1:2], weights[2:-1:2] = 4, 2
    return np.tensordot(weights, mats, axes=1) / (3 * (samples - 1))


@pytest.mark.parametrize("scale", [1e-7, 1e-3, 0.049, 0.051, 0.4, 2.0, 3.0])
def test_accumulated_rotation_is_the_path_integral_of_rotations(scale):
    w = scale * np.array([0.3, -0.8, 0.52]) / np.linalg.norm([0.3, -0.8, 0.52])
    np.testing.assert_allclose(accumulated_rotation_matrix(w), _path_integral(w), atol=1e-12)


@pytest.mark.parametrize("scale", [1e-6, 0.03, 0.049, 0.051, 0.7, 2.5])
def test_jacobian_matches_finite_differences(scale):
    rng = np.random.default_rng(7)
    w = scale * rng.normal(size=(4, 3)) / np.sqrt(3)
    d = rng.normal(size=(4, 3))
    g, rot, dg_dw = rotate_accumulated_jacobian(w, d)
    np.testing.assert_allclose(g, rotate_accumulated(w, d), atol=1e-14)
    np.testing.assert_allclose(rot @ d[..., None], g[..., None], atol=1e-14)
    eps = 1e-6
    numeric = np.stack(
        [(rotate_accumulated(w + eps * e, d) - rotate_accumulated(w - eps * e, d)) / (2 * eps) for e in np.eye(3)],
        axis=-1,
    )
    np.testing.assert_allclose(dg_dw, numeric, atol=1e-8)


def test_warp_kernel_equals_numpy_reference():
    rng = np.random.default_rng(11)
    w = rng.normal(size=(3, 500, 3)) * np.array([1e-6, 0.04, 1.5])[:, None, None]
    d = rng.normal(size=(3, 500, 3)) * 0.01
    np.testing.assert_allclose(rotate_accumulated_compiled(w, d), rotate_accumulated(w, d), rtol=0, atol=1e-10 * 0.01)
    assert np.abs(rotate_accumulated_compiled(w, d) - rotate_accumulated(w, d)).max() < 1e-10


def test_warping_turns_an_infinitesimal_rotation_into_an_exact_rotation():
    """ũ = R̃(θ)(θ × x) = (R(θ) - I) x: rigid, so the volume is kept exactly."""
    mesh = box_mesh(4, 2, 2, (0.04, 0.02, 0.02))
    theta = np.array([0.0, 0.0, 1.2])  # 69 degrees
    lin = np.cross(theta, mesh.points)
    warped = rotate_accumulated(np.broadcast_to(theta, lin.shape), lin)
    exact = Rotation.from_rotvec(theta).apply(mesh.points) - mesh.points
    np.testing.assert_allclose(warped, exact, atol=1e-14)


def test_warping_keeps_the_volume_of_a_strongly_bent_bar():
    model = _bar_model()
    basis = model.basis(6, cache=False)
    # Scale the first bending mode until the linear tip deflection is half the bar's length.
    mode = basis.phi[:, 0].reshape(-1, 3)
    q = np.zeros(6)
    q[0] = 0.06 / np.abs(mode).max()
    lin = model.displacement(q, warping=False)
    warped = model.displacement(q, warping=True)
    dv_lin, dv_warp = model.volume_change(np.stack([lin, warped]))
    assert abs(dv_lin) > 0.05  # the linear model inflates a strongly bent bar
    assert abs(dv_warp) < 0.2 * abs(dv_lin)


def test_volume_change_from_the_surface_equals_the_tet_sum():
    model = _bar_model(nx=5)
    rng = np.random.default_rng(2)
    disp = rng.normal(size=(3, model.mesh.n_nodes, 3)) * 1e-3
    tet_sum = model.mesh.tet_volumes(model.mesh.points + disp[1]).sum() / model.rest_volume - 1
    assert model.volume_change(disp)[1] == pytest.approx(tet_sum, abs=1e-13)
    stretch = np.zeros_like(disp[:1])
    stretch[0, :, 0] = 0.1 * model.mesh.points[:, 0]  # 10 % longer, same section
    assert model.volume_change(stretch)[0] == pytest.approx(0.1, rel=1e-12)


def test_warp_and_numpy_reconstruction_agree_on_a_model():
    model = _bar_model(nx=6)
    q = np.random.default_rng(4).normal(size=(5, 8)) * 1e-3
    fast = model.displacements(q, warping=True, backend="warp")
    ref = model.displacements(q, warping=True, backend="numpy")
    assert np.abs(fast - ref).max() < 1e-10


def test_float32_rendering_path_is_close_to_float64():
    model = _bar_model(nx=6)
    q = np.random.default_rng(5).normal(size=(4, 8)) * 2e-3
    d64 = model.displacements(q)
    d32 = model.displacements(q, dtype=np.float32)
    assert d32.dtype == np.float32
    assert np.abs(d32 - d64).max() < 1e-5 * np.abs(d64).max()


def test_volume_kernel_equals_numpy():
    model = _bar_model(nx=5)
    disp = np.random.default_rng(9).normal(size=(300, model.mesh.n_nodes, 3)) * 2e-3
    np.testing.assert_allclose(model.volume_change(disp), model.volume_change(disp, backend="numpy"), rtol=0, atol=1e-13)
