"""Seed 001's quadratic domains (tonguevis.sim.domains) against the full StVK reference.

Static displacement errors against the full-mesh StVK (:mod:`tonguevis.sim.stvk`), sensor nodes
held exactly at the targets, anchors fixed, measured when these tests were written
(2026-12-03; RMS / max over all nodes, mm; the reference's own RMS / max in brackets):

bar 60 x 10 x 10 mm, root fixed, tip-centre node prescribed, 2 domains (tip, centre), 60 modes:
    tip up 10 mm  [5.23 / 10.2]: domains 0.75 / 1.35, linear FEM 0.25 / 0.44, linear modal 0.25 / 0.44, warped 0.22 / 0.32
    tip up 20 mm  [10.8 / 20.5]: domains 1.37 / 2.48, linear FEM 1.14 / 1.99, linear modal 1.13 / 1.98, warped 1.10 / 1.64
    tip (5, 0, 15) [8.66 / 16.4]: domains 0.98 / 1.80, linear FEM 1.09 / 1.79, linear modal 1.13 / 1.78, warped 1.18 / 1.63
shipped tongue, sensors TT TD TL TR (5 domains, 150 DOFs), 100 modes:
    TT up 10 mm, others held [2.45 / 10.0]: domains 0.94 / 3.40, linear FEM 1.31 / 3.74, modal 2.51 / 12.9, warped 2.30 / 9.83
    raise (TT 15, TD 10, TL TR 12 mm up) [5.26 / 15.0]: domains 1.43 / 5.13, linear FEM 0.43 / 0.94, modal 1.36 / 4.10, warped 1.72 / 3.87
    retract (TT (-12,0,5), TD (-10,0,8), TL TR (-10,0,5)) [5.50 / 13.5]: domains 1.31 / 4.80, linear FEM 0.81 / 2.07,
        modal 1.91 / 4.17, warped 1.61 / 4.14
    tip up 20 (TT (3,0,20), TD 5, TL TR 8 mm up) [5.81 / 20.2]: domains 1.84 / 8.97, linear FEM 1.37 / 4.19,
        modal 2.78 / 13.5, warped 3.07 / 15.3
So: on the tongue the domains are closer to StVK than warping in all four loads and than the linear
modal model in three; the full linear FEM (no reduction) is closer still in three: at 10-20 mm the
nonlinearity costs less than the reduction to 150 DOFs does.  On the bar, two domains are the
coarsest subspace of all.
"""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from tonguevis.mesh.structured import box_mesh
from tonguevis.sim.domains import DomainModel, _dofs, load_weights, save_weights
from tonguevis.sim.model import TongueModel
from tonguevis.sim.stvk import solve_static


@pytest.fixture(scope="module")
def bar():
    mesh = box_mesh(12, 2, 2, (0.06, 0.01, 0.01))
    x = mesh.points
    root = np.flatnonzero(np.isclose(x[:, 0], 0.0))
    tip = int(np.flatnonzero(np.all(np.isclose(x, [0.06, 0.005, 0.005]), axis=1))[0])
    model = TongueModel(mesh, SimpleNamespace(sensors={"TT": tip}, anchors=root))
    return model, np.array([tip]), DomainModel(model, [tip], cache=False)


@pytest.fixture(scope="module")
def tongue():
    model = TongueModel.default()
    nodes = np.array([model.landmarks.sensors[k] for k in ("TT", "TD", "TL", "TR")])
    return model, nodes, DomainModel(model, nodes, cache=False)


def _errors(model, nodes, dm, targets, modes):
    """{method: (rms, max) mm} of each model's static shape against the full StVK, and the reference's own."""
    from tonguevis.analysis.quasistatic import quasi_static

    ref = solve_static(dm.solid, fixed=model.anchors, prescribed=(nodes, targets), steps=4, tol=1e-7)
    assert ref.converged
    z, ok = dm.solve_static(targets, steps=1)
    assert ok
    basis = model.basis(modes, cache=False)
    s = len(nodes)
    phi_s = basis.phi[_dofs(nodes)].reshape(s, 3, -1)
    w_s = model.rotation_matrix(basis)[_dofs(nodes)].reshape(s, 3, -1)
    q_lin, _, _ = quasi_static(basis.eigenvalues, phi_s, w_s, targets[None], warping=False)
    q_warp, ok_w, _ = quasi_static(basis.eigenvalues, phi_s, w_s, targets[None], warping=True)
    assert ok_w[0]
    k = model.stiffness
    given = np.zeros(k.shape[0], dtype=bool)
    given[_dofs(model.anchors)] = True
    given[_dofs(nodes)] = True
    lin = np.zeros(k.shape[0])
    lin[_dofs(nodes)] = targets.ravel()
    lin[~given] = spla.spsolve(k[~given][:, ~given].tocsc(), -(k[~given][:, given] @ lin[given]))
    shapes = {"domains": dm.displacement(z), "linear FEM": lin.reshape(-1, 3),
              "linear modal": model.displacement(q_lin[0], warping=False),
              "warped": model.displacement(q_warp[0], warping=True)}
    np.testing.assert_allclose(shapes["domains"][nodes], targets, atol=1e-12)  # hard constraints hold
    out = {}
    for name, u in shapes.items():
        e = np.linalg.norm(u - ref.u, axis=1)
        out[name] = (1e3 * np.sqrt(np.mean(e ** 2)), 1e3 * e.max())
    size = np.linalg.norm(ref.u, axis=1)
    # the subspace minimum of the same energy under the same constraints cannot be below the full one
    assert dm.energy(z) >= dm.solid.energy(ref.u) * (1 - 1e-9)
    return out, (1e3 * np.sqrt(np.mean(size ** 2)), 1e3 * size.max())


def test_weights_and_basis(tongue):
    model, nodes, dm = tongue
    w, seeds = dm.domains.weights, dm.domains.seeds
    assert len(seeds) == len(nodes) + 1 and dm.n_dofs == 30 * len(seeds)  # 4 sensors + centre, 30 DOFs each
    np.testing.assert_allclose(w[seeds], np.eye(len(seeds)), atol=1e-9)  # 1 at its seed, 0 at the others
    assert np.all(w[model.anchors] == 0) and w.min() >= 0 and w.max() <= 1
    np.testing.assert_allclose(np.linalg.norm(dm.domains.directions, axis=1), 1.0)
    assert set(np.unique(dm.domains.partition)) == set(range(len(seeds)))  # flooding reaches every domain
    eye = dm.basis.T @ (model.mass @ dm.basis)
    np.testing.assert_allclose(eye, np.eye(dm.n_dofs), atol=1e-8)
    stiff = dm.basis.T @ (model.stiffness @ dm.basis)
    np.testing.assert_allclose(stiff, np.diag(dm.eigenvalues), atol=1e-8 * dm.eigenvalues.max())
    assert np.abs(dm.basis[_dofs(model.anchors)]).max() == 0.0  # the anchors never move


def test_reduced_force_and_tangent(bar):
    _, _, dm = bar
    rng = np.random.default_rng(0)
    z = 2e-3 * rng.standard_normal(dm.n_dofs)
    fast, plain = dm.force(z), dm.force_through_gradients(z)
    np.testing.assert_allclose(fast, plain, atol=1e-11 * np.abs(plain).max())
    np.testing.assert_allclose(fast, dm.basis.T @ dm.solid.internal_force(dm.displacement(z)).ravel(),
                               atol=1e-11 * np.abs(plain).max())
    k, eps = dm.tangent(z), 1e-8
    dz = rng.standard_normal(dm.n_dofs)
    fd = -(dm.force(z + eps * dz) - dm.force(z - eps * dz)) / (2 * eps)
    assert np.abs(fd - k @ dz).max() <= 1e-6 * np.abs(fd).max()
    np.testing.assert_allclose(dm.energies(np.stack([z, 2 * z]))[0], dm.energy(z), rtol=1e-12)


def test_small_displacement_is_the_linear_subspace_solution(bar):
    model, nodes, dm = bar
    c = np.array([[0.0, 0.0, 1e-6]])
    z, ok = dm.solve_static(c, steps=1)
    assert ok
    rows = dm.rows(nodes).reshape(-1, dm.n_dofs)
    lam = dm.eigenvalues
    z_lin = (rows / lam).T @ np.linalg.solve((rows / lam) @ rows.T, c.ravel())  # min ½zᵀΛz s.t. Rz = c
    np.testing.assert_allclose(z, z_lin, atol=1e-4 * np.abs(z_lin).max())


@pytest.mark.parametrize("lift, bound", [([0, 0, 10], 0.2), ([0, 0, 20], 0.2), ([5, 0, 15], 0.15)])
def test_bar_against_stvk(bar, lift, bound):
    model, nodes, dm = bar
    errors, size = _errors(model, nodes, dm, np.array([lift], dtype=float) * 1e-3, modes=60)
    print(f"\nbar tip {lift} mm [{size[0]:.2f} / {size[1]:.2f}]:",
          ", ".join(f"{k} {a:.2f} / {b:.2f}" for k, (a, b) in errors.items()))
    assert errors["domains"][0] < bound * size[0]


TONGUE_LOADS = {
    "tip up 10": ({"TT": [0, 0, 10]}, 0.45),
    "raise": ({"TT": [0, 0, 15], "TD": [0, 0, 10], "TL": [0, 0, 12], "TR": [0, 0, 12]}, 0.3),
}


@pytest.mark.parametrize("load", sorted(TONGUE_LOADS))
def test_tongue_against_stvk(tongue, load):
    model, nodes, dm = tongue
    case, bound = TONGUE_LOADS[load]
    targets = np.array([case.get(k, [0, 0, 0]) for k in ("TT", "TD", "TL", "TR")], dtype=float) * 1e-3
    errors, size = _errors(model, nodes, dm, targets, modes=100)
    print(f"\ntongue {load} [{size[0]:.2f} / {size[1]:.2f}]:",
          ", ".join(f"{k} {a:.2f} / {b:.2f}" for k, (a, b) in errors.items()))
    assert errors["domains"][0] < bound * size[0]
    assert errors["domains"][0] < errors["warped"][0]  # closer to StVK than modal warping, both loads


def test_dynamics_settle_on_the_static_solution(bar):
    model, nodes, dm = bar
    target = np.array([[0.0, 0.0, 0.015]])
    frames = 200
    ramp = np.minimum(1.0, np.arange(1, frames + 1) / 20.0)
    targets = ramp[:, None, None] * target[None]
    result = dm.integrate(targets, 0.01, alpha=30.0, beta=0.0)
    assert result.converged.all() and not result.recovered.any()
    assert np.nanmax(result.residual) < 1e-12
    z_static, ok = dm.solve_static(target, steps=1)
    assert ok
    np.testing.assert_allclose(dm.displacement(result.q[-1]), dm.displacement(z_static),
                               atol=1e-4 * np.abs(dm.displacement(z_static)).max())
    # a sensor that stops acting (NaN) is let go, not held: the shape relaxes toward rest
    targets[100:] = np.nan
    relaxed = dm.integrate(targets, 0.01, alpha=30.0, beta=0.0)
    assert np.abs(dm.displacement(relaxed.q[-1])).max() < 0.05 * np.abs(dm.displacement(z_static)).max()


def test_weights_cache_round_trip(tmp_path, bar):
    _, _, dm = bar
    path = tmp_path / "domains.npz"
    save_weights(dm.domains, path)
    back = load_weights(path, dm.domains.key)
    np.testing.assert_array_equal(back.weights, dm.domains.weights)
    np.testing.assert_array_equal(back.seeds, dm.domains.seeds)
    assert load_weights(path, "another key") is None
    path.write_bytes(b"not a zip")
    assert load_weights(path, dm.domains.key) is None


def test_basis_cache_round_trip_and_a_broken_file_is_computed_again(tmp_path, monkeypatch):
    from tonguevis.sim.domains import _basis_path, _load_basis, _save_basis

    monkeypatch.setenv("TONGUEVIS_CACHE", str(tmp_path))
    rng = np.random.default_rng(0)
    eigenvalues, dofs, basis = rng.random(5), np.arange(12), rng.random((12, 5))
    _save_basis("k1", eigenvalues, dofs, basis)
    back = _load_basis("k1")
    for got, want in zip(back, (eigenvalues, dofs, basis)):
        np.testing.assert_array_equal(got, want)
    assert _load_basis("k2") is None  # another key: nothing cached for it
    _basis_path("k1").write_bytes(b"truncated")
    assert _load_basis("k1") is None


def _first_seconds(recording, seconds):
    n = int(seconds * recording.rate)
    cut = {k: v[:n] for k, v in recording.sensors.items()}
    return recording.with_sensors(cut, times=recording.times[:n], audio=None, labels=[],
                                  orientations={k: v[:n] for k, v in recording.orientations.items()})


def test_simulate_method_domains_gives_the_modal_methods_motion():
    from tonguevis.errors import SimulationError
    from tonguevis.io import read_recording
    from tonguevis.paths import DATA_DIR
    from tonguevis.sim.simulate import simulate

    rec = _first_seconds(read_recording(DATA_DIR / "spk1_ta.tsv"), 6.5)  # 5 s of rest, then /ta/
    warped = simulate(rec, method="warped", sensor_patches=None)  # the domains hold the sensor nodes themselves
    linear = simulate(rec, method="linear", sensor_patches=None)
    np.testing.assert_array_equal(linear.q, simulate(rec, warping=False, sensor_patches=None).q)  # warping= works
    assert warped.warping and not linear.warping
    domains = simulate(rec, method="domains")
    assert domains.metadata["method"] == "domains"
    assert set(warped.metadata) <= set(domains.metadata)  # every key of the modal methods
    p = domains.metadata["plausibility"]
    assert p["volume_change_max_percent"] < 2.0 and p["amplification"] < 2.0
    assert p["sensor_misfit_max_mm"] < 2.0  # held to the compliant targets (as the modal methods are)
    d = domains.displacements(slice(-1, None))[0]
    np.testing.assert_allclose(d, domains.model.domain_model.displacement(domains.q[-1]), atol=1e-15)
    assert domains.energy.max() > 0 and np.all(np.isfinite(domains.energy))
    with pytest.raises(SimulationError, match="unknown simulation method"):
        simulate(rec, method="fem")
    # What `tonguevis simulate` says of each (issue 37: the domains run said "180 modes, linear").
    from tonguevis.cli.simulate import summary

    said = {name: summary(motion)[0] for name, motion in (("warped", warped), ("linear", linear), ("domains", domains))}
    assert ", 100 modes, modal warping;" in said["warped"] and ", 100 modes, linear;" in said["linear"]
    d = domains.metadata["domains"]
    assert f", {d['domains']} quadratic domains ({d['dofs']} degrees of freedom), nonlinear tissue" in said["domains"]
    assert "modes" not in said["domains"] and not re.search(r"\blinear\b", said["domains"]), said["domains"]


def test_a_saved_domains_motion_loads_with_its_subspace(tmp_path, bar):
    from tonguevis.sim.domains import domains_model
    from tonguevis.sim.motion import Motion

    model, nodes, dm = bar
    dmodel = domains_model(model, dm)
    z = 1e-3 * np.random.default_rng(2).standard_normal((3, dm.n_dofs))
    motion = Motion(times=np.arange(3) / 100.0, q=z, model=dmodel, warping=False, sensor_names=["TT"],
                    sensor_nodes=nodes, targets=np.zeros((3, 1, 3)), sensor_residual=np.zeros((3, 1)),
                    energy=dm.energies(z), volume_change=np.zeros(3), converged=np.ones(3, dtype=bool),
                    metadata={"method": "domains", "domains": {"seeds": dm.domains.seeds.tolist()}})
    motion.save(tmp_path / "m.npz")
    back = Motion.load(tmp_path / "m.npz")
    np.testing.assert_allclose(back.displacements(), motion.displacements(), atol=1e-12)


def test_cubature_force_tangent_and_motion(tongue):
    from tonguevis.sim.cubature import Cubature, training_poses

    model, nodes, dm = tongue
    cub = Cubature(dm, poses=training_poses(dm, count=8), tolerance=0.02, max_tets=240)
    other = training_poses(dm, count=6, seed=7)
    error = cub.relative_error(other)
    print(f"\ncubature: {len(cub.tets)} of {len(model.mesh.tets)} tets, force error {100 * cub.training_error:.1f} % "
          f"(training), {100 * error:.1f} % (other shapes)")
    assert len(cub.tets) <= 240 + 8 and error < 0.1
    z = other[0]
    k, eps = cub.tangent(z), 1e-8
    dz = np.random.default_rng(0).standard_normal(dm.n_dofs)
    fd = -(cub.force(z + eps * dz) - cub.force(z - eps * dz)) / (2 * eps)
    assert np.abs(fd - k @ dz).max() <= 1e-6 * np.abs(fd).max()
    again = Cubature.from_weights(dm, cub.tets, cub.weights, cub.training_error)
    np.testing.assert_array_equal(again.force(z), cub.force(z))
    # a 0.5 s raise of the four sensors by 12 mm, held 0.5 s: the motion with and without the cubature
    ramp = np.minimum(1.0, np.arange(1, 101) / 50.0)
    targets = ramp[:, None, None] * np.array([[0, 0, 12], [0, 0, 8], [0, 0, 10], [0, 0, 10]])[None] * 1e-3
    full = dm.integrate(targets, 0.01, 6.22, 0.11)
    dm.use_cubature(cub)
    try:
        fast = dm.integrate(targets, 0.01, 6.22, 0.11)
    finally:
        dm.use_cubature(None)
    assert fast.converged.all()
    diff = np.linalg.norm(dm.displacement(fast.q) - dm.displacement(full.q), axis=2)
    size = np.linalg.norm(dm.displacement(full.q), axis=2)
    print(f"cubature vs every tet over the motion: largest node difference {1e3 * diff.max():.3f} mm "
          f"(largest displacement {1e3 * size.max():.1f} mm)")
    # measured: 2.26 of 14.8 mm with this small cubature (202 tets, 7.1 % force error on other shapes);
    # the default one (cubature_for: 344 tets, 3.9 %) 1.80 mm: not yet accurate enough to be the default
    assert diff.max() < 0.2 * size.max()


# ---------------------------------------------------------------------------------------- the fast path (issue 26 item 5)
def test_compiled_force_energy_and_tangent_equal_the_numpy_reference(tongue):
    from tonguevis.sim.cubature import training_poses

    model, nodes, dm = tongue
    assert dm.backend == "warp"
    compiled = dm.compiled
    poses = training_poses(dm, count=3, seed=5)  # 5-20 mm sensor displacements
    for z in poses:
        ref = dm.full_force(z)
        np.testing.assert_allclose(compiled.force(z), ref, rtol=0, atol=1e-12 * np.abs(ref).max())
        assert compiled.last_energy == pytest.approx(dm.energy(z), rel=1e-12)
        assert dm.energy(z) > 0
        k_ref = dm.full_tangent(z)
        np.testing.assert_allclose(compiled.tangent(z), k_ref, rtol=0, atol=1e-12 * np.abs(k_ref).max())
    np.testing.assert_allclose(dm.force(poses[0]), dm.full_force(poses[0]), rtol=1e-12)  # dispatch
    plain = DomainModel(model, nodes, cache=False, backend="numpy")
    np.testing.assert_allclose(dm.energies(poses), plain.energies(poses), rtol=1e-12)
    with pytest.raises(ValueError, match="backend"):
        DomainModel(model, nodes, cache=False, backend="fortran")


def _raise_with_a_dropout():
    """100 frames at 100 Hz: the four sensors raised 8-12 mm over 0.5 s and held; TL drops out for 20 frames."""
    ramp = np.minimum(1.0, np.arange(1, 101) / 50.0)
    targets = ramp[:, None, None] * np.array([[0, 0, 12], [0, 0, 8], [0, 0, 10], [0, 0, 10]])[None] * 1e-3
    targets[40:60, 2] = np.nan
    return targets


def test_fast_newton_within_a_micrometre_of_the_reference_integrator(tongue):
    model, nodes, dm = tongue
    targets = _raise_with_a_dropout()
    plain = DomainModel(model, nodes, cache=False, backend="numpy")
    ref = plain.integrate(targets, 0.01, 6.22, 0.11)  # today's solve: NumPy force, Newton to 0.1 µm
    assert ref.converged.all()
    fast, energy = dm.integrate_fast(targets, 0.01, 6.22, 0.11)
    assert fast.converged.all() and not fast.recovered.any()
    diff = np.linalg.norm(dm.displacement(fast.q) - dm.displacement(ref.q), axis=2)
    size = np.linalg.norm(dm.displacement(ref.q), axis=2)
    print(f"\nfast Newton vs reference: largest node difference {1e6 * diff.max():.3f} µm of {1e3 * size.max():.1f} mm; "
          f"forces {fast.iterations.sum()} against {ref.iterations.sum()}")
    assert diff.max() < 1e-5  # 0.01 mm (measured 3.4 µm; 191 forces against 225)
    assert fast.iterations.sum() < ref.iterations.sum()
    np.testing.assert_allclose(fast.residual, ref.residual, atol=1e-9, equal_nan=True)  # the same sensors act
    assert np.isnan(fast.residual[40:60, 2]).all()
    # the energy carried to the accepted shape equals the energy measured there
    np.testing.assert_allclose(energy, dm.energies(fast.q), rtol=1e-5)
    # the NumPy force in the fast loop gives the same motion as the compiled one
    again, energy_again = plain.integrate_fast(targets, 0.01, 6.22, 0.11)
    np.testing.assert_allclose(again.q, fast.q, atol=1e-9 * np.abs(fast.q).max())
    np.testing.assert_allclose(energy_again, energy, rtol=1e-5)


def test_linearised_step_has_its_stated_cost(tongue):
    model, nodes, dm = tongue
    targets = _raise_with_a_dropout()
    ref, _ = dm.integrate_fast(targets, 0.01, 6.22, 0.11, tolerance=1e-8)
    lin, energy = dm.integrate_fast(targets, 0.01, 6.22, 0.11, linearised=True)
    assert (lin.iterations == 1).all()
    diff = np.linalg.norm(dm.displacement(lin.q) - dm.displacement(ref.q), axis=2)
    print(f"\nlinearised vs converged: largest node difference {1e3 * diff.max():.3f} mm, "
          f"RMS {1e3 * np.sqrt((diff ** 2).mean()):.4f} mm")
    # measured 0.15 mm (RMS 0.004 mm) on this 12 mm raise in 0.5 s (1.69 mm without the carried first step)
    assert 1e-6 < diff.max() < 1e-3
    np.testing.assert_allclose(energy, dm.energies(lin.q), rtol=1e-12)  # measured afresh


def test_the_basis_cache_gives_the_same_model(tmp_path, monkeypatch):
    from tonguevis.sim.domains import _basis_path

    monkeypatch.setenv("TONGUEVIS_CACHE", str(tmp_path))
    model = TongueModel.default()
    nodes = np.array([model.landmarks.sensors[k] for k in ("TT", "TD")])
    built = DomainModel(model, nodes)
    assert _basis_path(built.domains.key).exists()
    loaded = DomainModel(model, nodes)
    np.testing.assert_array_equal(loaded.basis, built.basis)
    np.testing.assert_array_equal(loaded.eigenvalues, built.eigenvalues)
    np.testing.assert_array_equal(loaded.domain_dofs, built.domain_dofs)
    _basis_path(built.domains.key).write_bytes(b"not a zip")
    again = DomainModel(model, nodes)  # unreadable: computed again
    np.testing.assert_allclose(again.basis, built.basis, atol=1e-12 * np.abs(built.basis).max())
