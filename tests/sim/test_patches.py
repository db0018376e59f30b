"""Sensor patches: every measured sensor on the surface, local shapes, the energy of the shape drawn."""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.io import read_recording
from tonguevis.paths import DATA_DIR
from tonguevis.sim import Motion, simulate
from tonguevis.sim.patches import PATCH_REACH, augmented_basis, augmented_model, close_sensor_gaps, global_part


@pytest.fixture(scope="module")
def patched(model, demo):
    return simulate(demo, model, modes=40, sensor_patches="default", humps=False)  # the local shapes alone


def test_every_measured_sensor_is_on_its_node(model, demo, patched):
    plain = simulate(demo, model, modes=40, sensor_patches=None)
    assert plain.metadata["plausibility"]["sensor_misfit_max_mm"] > 0.2  # the modes alone leave a gap
    assert np.nanmax(patched.sensor_residual) < 1e-9
    # ... the same, measured on the reconstructed mesh (warped), not on the solver's own rows
    nodes = patched.sensor_nodes
    u = patched.displacements(slice(0, None, 50), nodes=nodes)
    measured = patched.targets[::50] - patched.model.mesh.points[nodes][None]
    ok = np.all(np.isfinite(measured), axis=2)
    assert np.abs(u - measured)[ok].max() < 1e-9
    p = patched.metadata["plausibility"]
    assert 0.8 <= p["amplification"] <= 1.5 and p["volume_change_max_percent"] < 1.0
    assert patched.metadata["sensor_patches"]["global_modes"] == 40 and patched.q.shape[1] == 40 + 3 * len(nodes)


def test_patch_shapes_are_local(model, patched):
    basis = patched.model.basis(patched.q.shape[1])
    points = model.mesh.points
    for k, node in enumerate(patched.sensor_nodes):
        shape = basis.phi[:, 40 + 3 * k: 40 + 3 * k + 3].reshape(-1, 3, 3)
        far = np.linalg.norm(points - points[node], axis=1) > PATCH_REACH
        assert np.abs(shape[far]).max() == 0.0 and np.abs(shape[~far]).max() > 0.0


def test_the_energy_is_that_of_the_shape_drawn(model, patched):
    """½ qᵀK_r q with the patches' coupling equals ½ uᵀKu of the (linear) displacement field."""
    q = patched.q[::97]
    u = patched.model.displacements(q, warping=False).reshape(len(q), -1)
    direct = 0.5 * np.einsum("fi,fi->f", u, (patched.model.stiffness @ u.T).T)
    np.testing.assert_allclose(patched.model.energy(q), direct, rtol=1e-9)


def test_closing_the_gaps_against_a_simple_reference(model):
    """The batched solve equals a per-frame, per-equation reference (warped node = measurement)."""
    from tonguevis.sim.rotation import rotate_accumulated

    base = model.basis(30)
    nodes = np.array(sorted(model.landmarks.sensors.values()))[:3]
    aug = augmented_basis(model, base, nodes)
    rotation = augmented_model(model, aug).rotation_matrix(aug)
    rng = np.random.default_rng(1)
    q = rng.normal(0, 2e-5, (4, 30))
    measured = rng.normal(0, 2e-3, (4, len(nodes), 3))
    measured[2, 1] = np.nan  # not measured: that patch stays at rest
    c = close_sensor_gaps(aug, rotation, nodes, q, measured, warping=True)
    full = np.hstack([q, c])
    for f in range(4):
        for s, node in enumerate(nodes):
            rows = slice(3 * node, 3 * node + 3)
            moved = rotate_accumulated((rotation[rows] @ full[f])[None], (aug.phi[rows] @ full[f])[None])[0]
            if np.isfinite(measured[f, s]).all():
                np.testing.assert_allclose(moved, measured[f, s], atol=1e-12)
    assert np.all(c[2, 3:6] == 0.0)


def test_saved_and_loaded_with_its_patches(patched, tmp_path):
    patched.save(tmp_path / "m.npz")
    again = Motion.load(tmp_path / "m.npz")
    np.testing.assert_allclose(again.displacement(300), patched.displacement(300), atol=1e-15)
    model, q = global_part(again)
    assert q.shape[1] == 40 and model.basis(40).n_modes == 40


def test_morphing_patched_motions_uses_their_modes(model, demo, patched):
    from tonguevis.analysis.morph import morph_between

    other = simulate(read_recording(DATA_DIR / "spk2_ka.tsv", sensor_map=DATA_DIR / "sensor_map.json"), model,
                     modes=40, sensor_patches="default")
    morph = morph_between(patched, 6.0, other, 6.2)
    assert morph.q_source.shape == (40,)
    np.testing.assert_allclose(morph.q_source, patched.q[patched.frame_at(6.0), :40])


def test_a_bad_radius_is_refused(model, demo):
    from tonguevis.errors import SimulationError

    with pytest.raises(SimulationError, match="patches' radius"):
        simulate(demo, model, modes=10, sensor_patches=-1.0)


def test_held_out_sensors_beyond_the_humps_are_predicted_as_without_them(model, demo):
    """With the humps (the default) the drivers' shapes reach HUMP_REACH: a held-out node farther than that
    from every humped driver and PATCH_REACH from every driver moves as with the modes alone, and one nearer
    moves otherwise."""
    from tonguevis.analysis.validation import validate
    from tonguevis.sim.patches import HUMP_REACH, humped_sensors

    plain = validate(demo, model, modes=40, quasi_static=False, sensor_patches=None)
    humped = validate(demo, model, modes=40, quasi_static=False, sensor_patches="default", humps=True)
    points = model.mesh.points
    nodes = {name: item.node for name, item in plain.held_out.items()}
    names = list(nodes)
    far = near = 0
    for name, item in humped.held_out.items():
        drivers = [n for n in names if n != name]
        with_hump = [nodes[drivers[k]] for k in humped_sensors(drivers)]
        d_all = np.linalg.norm(points[[nodes[n] for n in drivers]] - points[item.node], axis=1).min()
        d_hump = np.linalg.norm(points[with_hump] - points[item.node], axis=1).min() if with_hump else np.inf
        same = np.allclose(item.predicted["model"], plain.held_out[name].predicted["model"], atol=1e-12)
        if d_all > PATCH_REACH and d_hump > HUMP_REACH:
            assert same
            far += 1
        elif d_hump < HUMP_REACH - 1e-3:
            assert not same
            near += 1
    assert near >= 1


def test_held_out_sensors_beyond_the_patches_are_predicted_as_without_them(model, demo):
    """Leave-one-sensor-out: the drivers' patches close the drivers' gaps and reach no further
    than PATCH_REACH, so a held-out node farther from every driver moves as with the modes alone."""
    from tonguevis.analysis.validation import validate

    plain = validate(demo, model, modes=40, quasi_static=False, sensor_patches=None)
    patched = validate(demo, model, modes=40, quasi_static=False, sensor_patches="default", humps=False)
    points = model.mesh.points
    nodes = {name: item.node for name, item in plain.held_out.items()}
    checked = 0
    for name, item in patched.held_out.items():
        others = [n for k, n in nodes.items() if k != name]
        if np.linalg.norm(points[others] - points[item.node], axis=1).min() > PATCH_REACH:
            np.testing.assert_allclose(item.predicted["model"], plain.held_out[name].predicted["model"], atol=1e-12)
            checked += 1
    assert checked >= 2
