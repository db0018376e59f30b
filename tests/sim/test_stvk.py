"""The full-mesh StVK reference (tonguevis.sim.stvk) against closed forms and the linear assembly.

Errors measured when these tests were written (2026-12-03):
* uniaxial tension/compression, lateral faces free: the axial stretch and the lateral
  stretch equal the closed form to 1e-10 for stretches 1.001, 1.5 and 0.9 (the
  homogeneous deformation lies in the linear-tet space, so the mesh is exact);
* cantilever, end load, ν = 0, L/h = 10, tip deflection 1e-4 L: FE/Euler-Bernoulli − 1 =
  −0.150 (4 tets' cubes through the height), −0.038 (8); Richardson-extrapolated
  (O(h²): the error fell 3.9x when h halved) −0.0007, so within 1 % of Euler-Bernoulli
  (Timoshenko's shear term adds +0.6 % at this slenderness);
* tangent against central differences of the force: relative 1e-9;
  rest tangent against :func:`assemble_stiffness`: equal to round-off (0.0 measured).
"""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.mesh.structured import box_mesh
from tonguevis.sim.assembly import assemble_mass, assemble_stiffness
from tonguevis.sim.stvk import DynamicState, Dynamics, StVK, solve_static

E, NU = 6912.0, 0.49


def _end_face_loads(points, faces, x_end, traction):
    """(n, 3) consistent nodal forces (N) of a uniform traction (3,) Pa on the boundary faces at x = x_end."""
    end = faces[np.all(np.isclose(points[faces][:, :, 0], x_end), axis=1)]
    p = points[end]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    out = np.zeros_like(points)
    for axis in range(3):
        np.add.at(out[:, axis], end.ravel(), np.repeat(traction[axis] * area / 3.0, 3))
    return out


def _bar_rollers(points, width):
    """DOFs holding the x = 0 face on rollers (x) plus what stops the rigid motions, nothing else."""
    left = np.flatnonzero(np.isclose(points[:, 0], 0.0))
    origin = np.flatnonzero(np.all(np.isclose(points, 0.0), axis=1))[0]
    side = np.flatnonzero(np.isclose(points[:, 0], 0) & np.isclose(points[:, 1], width) & np.isclose(points[:, 2], 0))[0]
    return np.concatenate([3 * left, [3 * origin + 1, 3 * origin + 2, 3 * side + 2]])


def test_rest_tangent_is_the_linear_assembly_and_tangent_is_the_force_derivative():
    mesh = box_mesh(4, 2, 2, (0.04, 0.01, 0.01))
    solid = StVK(mesh.points, mesh.tets, E, NU)
    rest = solid.tangent(np.zeros((mesh.n_nodes, 3)))
    linear = assemble_stiffness(mesh.points, mesh.tets, E, NU)
    assert abs(rest - linear).max() <= 1e-12 * abs(linear).max()
    rng = np.random.default_rng(0)
    u = 0.003 * rng.standard_normal((mesh.n_nodes, 3))  # 3 mm on 5 mm cells: large strains
    k = solid.tangent(u)
    assert abs(k - linear).max() > 0.1 * abs(linear).max()  # not the linear one there
    eps = 1e-7
    for _ in range(3):
        du = rng.standard_normal(u.shape)
        fd = -(solid.internal_force(u + eps * du) - solid.internal_force(u - eps * du)).ravel() / (2 * eps)
        assert np.abs(fd - k @ du.ravel()).max() <= 1e-6 * np.abs(fd).max()
    # and the force is the negative gradient of the energy
    du = rng.standard_normal(u.shape)
    slope = (solid.energy(u + eps * du) - solid.energy(u - eps * du)) / (2 * eps)
    assert slope == pytest.approx(-np.sum(solid.internal_force(u) * du), rel=1e-6)


def test_rigid_rotation_costs_no_energy_and_no_force():
    mesh = box_mesh(3, 2, 2, (0.03, 0.02, 0.02))
    solid = StVK(mesh.points, mesh.tets, E, NU)
    c, s = np.cos(1.2), np.sin(1.2)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    u = mesh.points @ rot.T - mesh.points + [0.01, -0.02, 0.005]
    assert solid.energy(u) < 1e-20
    assert np.abs(solid.internal_force(u)).max() < 1e-14
    # the linear model is not invariant: it charges the same motion energy
    k = assemble_stiffness(mesh.points, mesh.tets, E, NU)
    assert 0.5 * u.ravel() @ (k @ u.ravel()) > 1e-6


@pytest.mark.parametrize("stretch", [1.001, 1.5, 0.9])
def test_bar_in_uniaxial_tension_follows_the_stvk_closed_form(stretch):
    """Lateral faces free: S₂₂ = S₃₃ = 0 gives E₂₂ = −ν E₁₁ exactly, so S₁₁ = E·E₁₁ and
    P₁₁ = F₁₁S₁₁ = (E/2) λ (λ² − 1), λ₂ = √(1 − ν(λ² − 1)).  (Small strain: P = E ε, Young's law.)"""
    length, width = 0.04, 0.01
    mesh = box_mesh(4, 2, 2, (length, width, width))
    solid = StVK(mesh.points, mesh.tets, E, NU)
    traction = 0.5 * E * stretch * (stretch ** 2 - 1.0)  # first Piola-Kirchhoff, force per rest area
    loads = _end_face_loads(mesh.points, mesh.boundary_faces(), length, [traction, 0, 0])
    result = solve_static(solid, fixed_dofs=_bar_rollers(mesh.points, width), loads=loads, steps=5)
    assert result.converged
    deformed = mesh.points + result.u
    end = np.isclose(mesh.points[:, 0], length)
    np.testing.assert_allclose(deformed[end, 0], stretch * length, rtol=1e-10)
    lateral = np.sqrt(1.0 - NU * (stretch ** 2 - 1.0))
    np.testing.assert_allclose(np.ptp(deformed[:, 1]) / width, lateral, rtol=1e-10)
    np.testing.assert_allclose(np.ptp(deformed[:, 2]) / width, lateral, rtol=1e-10)
    if stretch == 1.001:  # Young's modulus law at small strain, to first order
        assert traction / (stretch - 1.0) == pytest.approx(E, rel=2e-3)


def test_prescribed_end_displacement_gives_the_closed_form_reaction():
    length, width = 0.04, 0.01
    mesh = box_mesh(4, 2, 2, (length, width, width))
    solid = StVK(mesh.points, mesh.tets, E, NU)
    stretch = 1.3
    end = np.flatnonzero(np.isclose(mesh.points[:, 0], length))
    rollers = np.concatenate([_bar_rollers(mesh.points, width), 3 * end])
    u_end = np.zeros_like(mesh.points)
    u_end[end, 0] = (stretch - 1.0) * length
    # only the end's x DOFs are prescribed (held where u0 puts them); its y and z stay free
    result = solve_static(solid, fixed_dofs=rollers, u0=u_end, steps=1)
    assert result.converged
    force = -result.reaction[end, 0].sum()
    assert -force == pytest.approx(0.5 * E * stretch * (stretch ** 2 - 1.0) * width ** 2, rel=1e-10)


def _cantilever_tip_ratio(n: int) -> float:
    """FE tip deflection / Euler-Bernoulli's for an end-loaded cantilever with n cubes through the height."""
    length, height = 0.1, 0.01
    mesh = box_mesh(10 * n, n, n, (length, height, height))
    solid = StVK(mesh.points, mesh.tets, E, 0.0)  # ν = 0: the beam theory's uniaxial bending, no locking
    inertia = height ** 4 / 12
    load = 1e-4 * 3 * E * inertia / length ** 2  # Euler-Bernoulli tip deflection 1e-4 L: small
    loads = _end_face_loads(mesh.points, mesh.boundary_faces(), length, [0, 0, -load / height ** 2])
    root = np.flatnonzero(np.isclose(mesh.points[:, 0], 0.0))
    result = solve_static(solid, fixed=root, loads=loads)
    assert result.converged
    tip = np.isclose(mesh.points[:, 0], length)
    return float(-result.u[tip, 2].mean() / (load * length ** 3 / (3 * E * inertia)))


def test_cantilever_end_load_converges_to_euler_bernoulli():
    coarse, fine = _cantilever_tip_ratio(4), _cantilever_tip_ratio(8)
    assert 0.8 < coarse < fine < 1.0  # linear tets are too stiff in bending and converge from below
    assert (1 - coarse) / (1 - fine) == pytest.approx(4.0, rel=0.15)  # second order in h
    extrapolated = fine + (fine - coarse) / 3.0  # Richardson, O(h²)
    assert extrapolated == pytest.approx(1.0, abs=0.01)


def test_dynamic_step_at_small_amplitude_is_the_linear_backward_euler_step():
    mesh = box_mesh(6, 2, 2, (0.06, 0.01, 0.01))
    solid = StVK(mesh.points, mesh.tets, E, NU)
    root = np.flatnonzero(np.isclose(mesh.points[:, 0], 0.0))
    dyn = Dynamics(solid, dt=0.01, alpha=6.22, beta=0.11, fixed=root)
    rng = np.random.default_rng(1)
    v0 = 1e-7 * rng.standard_normal((mesh.n_nodes, 3))
    v0[root] = 0.0
    state, ok = dyn.step(DynamicState(np.zeros_like(v0), v0))
    assert ok
    h = 0.01
    k = assemble_stiffness(mesh.points, mesh.tets, E, NU)
    m = assemble_mass(mesh.points, mesh.tets, 1000.0)
    c = 6.22 * m + 0.11 * k
    free = np.ones(3 * mesh.n_nodes, dtype=bool)
    free[(3 * root[:, None] + np.arange(3)).ravel()] = False
    a = (m / h ** 2 + c / h + k).tocsc()[free][:, free]
    import scipy.sparse.linalg as spla

    du = np.zeros(3 * mesh.n_nodes)
    du[free] = spla.spsolve(a, (m @ v0.ravel() / h)[free])
    assert np.abs(state.u.ravel() - du).max() <= 1e-6 * np.abs(du).max()


def test_dynamic_steps_settle_on_the_static_solution():
    """Damped backward Euler under a constant prescribed end displacement ends at the static equilibrium."""
    mesh = box_mesh(6, 2, 2, (0.06, 0.01, 0.01))
    solid = StVK(mesh.points, mesh.tets, E, NU)
    root = np.flatnonzero(np.isclose(mesh.points[:, 0], 0.0))
    tip = np.flatnonzero(np.isclose(mesh.points[:, 0], 0.06))
    lift = np.tile([0.0, 0.0, 0.02], (len(tip), 1))  # 20 mm on a 60 mm bar: a large rotation
    static = solve_static(solid, fixed=root, prescribed=(tip, lift), steps=4)
    assert static.converged
    dyn = Dynamics(solid, dt=0.01, alpha=30.0, fixed=root)
    state = DynamicState(np.zeros((mesh.n_nodes, 3)), np.zeros((mesh.n_nodes, 3)))
    for i in range(300):
        frac = min(1.0, (i + 1) / 20)
        state, ok = dyn.step(state, prescribed=(tip, frac * lift))
        assert ok
    assert np.abs(state.u - static.u).max() < 1e-3 * np.abs(static.u).max()
    assert np.abs(state.u[tip] - lift).max() < 1e-15
