"""Sensor humps (RunSettings.humps): the tissue around a sensor moves with it, the palate flattens the humps."""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.io import read_recording
from tonguevis.sim import Motion, simulate
from tonguevis.sim.patch_contact import _least_distance, _null_space
from tonguevis.sim.patches import (HUMP_TILTS, augmented_basis, augmented_model, close_sensor_gaps, humped_sensors,
                                   patch_costs)


def _basis(model, n=3):
    base = model.basis(30)
    nodes = np.array(sorted(model.landmarks.sensors.values()))[:n]
    aug = augmented_basis(model, base, nodes, hump="scaled")
    return base, nodes, aug, augmented_model(model, aug).rotation_matrix(aug)


def test_the_humps_close_the_gaps_at_the_least_cost(model):
    """Every measured sensor on its node (warped), and the coordinates are the least-cost ones: equal to the
    minimum-norm solution of the same equations in the cost metric, computed by least squares per frame."""
    from tonguevis.sim.rotation import rotate_accumulated

    base, nodes, aug, rotation = _basis(model)
    s, m = len(nodes), 30
    assert aug.n_modes == m + 3 * s + 3 * (1 + HUMP_TILTS) * s
    rng = np.random.default_rng(2)
    q = rng.normal(0, 2e-5, (3, m))
    measured = rng.normal(0, 2e-3, (3, s, 3))
    measured[1, 2] = np.nan
    c = close_sensor_gaps(aug, rotation, nodes, q, measured, warping=True)
    full = np.hstack([q, c])
    cost = patch_costs(aug, nodes)
    tilts = np.tile(np.r_[np.zeros(3), np.ones(3 * HUMP_TILTS)], s).astype(bool)
    for f in range(3):
        acting = np.isfinite(measured[f]).all(axis=1)
        rows = []
        for k, node in enumerate(nodes):
            dofs = slice(3 * node, 3 * node + 3)
            if acting[k]:
                moved = rotate_accumulated((rotation[dofs] @ full[f])[None], (aug.phi[dofs] @ full[f])[None])[0]
                np.testing.assert_allclose(moved, measured[f, k], atol=1e-12)
                rows.append(dofs)
        # reference: the same equations (the patches' rows at the acting nodes = what the patches must add),
        # solved for the least Σ cost c² over the columns of the acting sensors, tilts left out, by lstsq
        dofs = np.concatenate([np.arange(r.start, r.stop) for r in rows])
        a = aug.phi[dofs, m:]
        owner = np.r_[np.repeat(np.arange(s), 3), np.repeat(np.arange(s), 3 * (1 + HUMP_TILTS))]
        free = acting[owner] & np.r_[np.ones(3 * s, bool), ~tilts]
        scale = 1.0 / np.sqrt(cost[free])
        target = a @ c[f]
        z = np.linalg.lstsq(a[:, free] * scale, target, rcond=None)[0]
        expected = np.zeros_like(c[f])
        expected[free] = z * scale
        np.testing.assert_allclose(c[f], expected, atol=1e-9 * np.abs(expected).max())
        assert np.all(c[f][~acting[owner]] == 0.0)


def test_a_hump_moves_its_neighbourhood_as_a_whole(model, demo):
    """On the demo /ka/, the dorsum sensor's node moves no more than 1.25 times the surface within 10 mm of
    it with the humps, and it stays on its sensor; without them the local shapes make a peak."""
    out = {}
    for humps in (False, True):
        motion = simulate(demo, model, modes=40, humps=humps)
        node = motion.sensor_nodes[motion.sensor_names.index("TD")]
        pts = model.mesh.points
        near = np.flatnonzero((np.linalg.norm(pts - pts[node], axis=1) < 10e-3))
        near = np.intersect1d(near, model.surface_nodes)
        near = near[near != node]
        ratios = []
        for i in range(0, len(motion.times), 25):
            u = motion.displacement(i)
            if np.linalg.norm(u[node]) > 3e-3:
                ratios.append(np.linalg.norm(u[node]) / np.mean(np.linalg.norm(u[near], axis=1)))
        out[humps] = max(ratios)
        assert np.nanmax(motion.sensor_residual) < 1e-9
    assert out[True] <= 1.25 < out[False] or out[True] < out[False] - 0.1


def test_humps_are_saved_and_loaded(model, demo, tmp_path):
    motion = simulate(demo, model, modes=40, humps=True)
    assert motion.metadata["sensor_patches"]["hump_mm"] is not None
    assert motion.metadata["sensor_patches"]["humped"] == humped_sensors(motion.sensor_names)
    path = tmp_path / "m.npz"
    motion.save(path)
    again = Motion.load(path)
    np.testing.assert_allclose(again.displacement(40), motion.displacement(40), atol=1e-12)


def test_least_distance_against_a_direct_qp():
    """Lawson-Hanson LDP equals SciPy's SLSQP on small random feasible problems."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(4)
    for _ in range(5):
        g = rng.normal(size=(7, 4))
        h = g @ rng.normal(0, 3.0, size=4) - rng.uniform(0.0, 0.5, 7)  # feasible, the origin mostly not
        z = _least_distance(g, h)
        ref = minimize(lambda x: x @ x, np.zeros(4), jac=lambda x: 2 * x, method="SLSQP",
                       constraints=[{"type": "ineq", "fun": lambda x: g @ x - h, "jac": lambda x: g}],
                       options={"ftol": 1e-14, "maxiter": 500}).x
        assert z is not None and np.all(g @ z - h >= -1e-9)
        assert np.all(g @ ref - h >= -1e-7)
        np.testing.assert_allclose(z, ref, atol=1e-5)
    assert _least_distance(np.array([[1.0], [-1.0]]), np.array([1.0, 0.0])) is None  # z >= 1 and z <= 0


def test_the_null_space_keeps_the_sensors_in_the_cost_metric(model):
    _, nodes, aug, _ = _basis(model)
    m = 30
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    rows = aug.phi[dofs, m:]
    cost = patch_costs(aug, nodes)
    null = _null_space(rows, cost)
    assert np.abs(rows @ null).max() < 1e-9 * np.abs(rows).max()
    np.testing.assert_allclose(null.T @ (cost[:, None] * null), np.eye(null.shape[1]), atol=1e-9)


@pytest.mark.parametrize("name", ["006_OSN12_Kah_nofb_natural_take2_HR", "007_OSN12_Kah_withFb_natural_HR"])
def test_on_real_ka_the_dorsum_rises_as_a_hump_under_the_palate(osn12_palate, name):
    """The shared /ka/ 006 and 007 with the speaker's palate, at the defaults (humps, the estimated roof raised
    broadly): the TD node moves at most 1.25 times as far as the dorsum within 10 mm of it at every closure found
    and wherever TD is highest (1.49 and 1.75 before: a cone), the sensors stay on their nodes, and the humps
    flattened against the palate leave the dorsum at most 1 mm inside it there."""
    from tests.conftest import shared_file
    from tonguevis.mesh import dorsal_surface_nodes

    recording = read_recording(shared_file("ema", "optispeech", f"{name}.tsv"))
    motion = simulate(recording, palate=str(osn12_palate))
    assert motion.metadata["sensor_patches"]["hump_mm"] is not None
    points = motion.model.mesh.points
    dorsum = dorsal_surface_nodes(motion.model.mesh)
    node = motion.sensor_nodes[motion.sensor_names.index("TD")]
    near = dorsum[(np.linalg.norm(points[dorsum] - points[node], axis=1) < 10e-3) & (dorsum != node)]
    frames = (motion.metadata["contact"].get("closures") or {}).get("maximum_constriction_frames") or []
    # /k/ closures: the TD sensor at its highest in each second of the recording
    td = motion.targets[:, motion.sensor_names.index("TD"), 2]
    peaks = [int(np.nanargmax(td[i:i + 100])) + i for i in range(0, len(td) - 100, 100)]
    checked = 0
    for f in sorted(set(peaks) | set(frames)):
        u = motion.displacement(f)
        if np.linalg.norm(u[node]) < 3e-3:
            continue
        checked += 1
        assert np.linalg.norm(u[node]) <= 1.25 * np.mean(np.linalg.norm(u[near], axis=1))
        pos = points + u + (motion.jaw_offset[f] if motion.jaw_offset is not None else 0.0)
        gap = motion.palate_at(f).clearance(pos[dorsum])[0]
        assert np.nanmin(gap) > -1e-3
    assert checked >= 5
    # drawn in: 2.2 % without the projection; 0.2-0.3 % before the dorsum was pressed at the closures, 0.6 and 1.3 %
    # with it (the pull raises the dorsum 2-5 mm onto the roof: the /ta/ 009's tip pull gives 1.2 %)
    assert motion.metadata["plausibility"]["volume_change_max_percent"] < 1.5
    assert np.nanmax(motion.sensor_residual) <= 1e-3 + 1e-9  # on the surface: the misfit bound
    # Nothing drawn inside the palate anywhere (the dorsum pressed at the closures, the pulled nodes held out
    # of it with the rest: 2.9 mm inside on 006 when the humps' projection left the pulled frames alone), and
    # the dorsum about TD within 0.5 mm of it at 8 or more of the 10 hand-labelled /k/ closures (7 and 8 of 10
    # when only TD's own node was drawn up to the roof).
    assert motion.penetration.max() < 0.2e-3
    textgrid = pytest.importorskip("praatio.textgrid")
    labelled = [e.time for e in textgrid.openTextgrid(str(shared_file("ema", "optispeech", f"{name}.labels.TextGrid")),
                                                     False).getTier("closure").entries]
    region = dorsum[(np.abs(points[dorsum, 0] - points[node, 0]) <= 10e-3)
                    & (np.abs(points[dorsum, 1] - points[node, 1]) <= 8e-3)]
    touching = 0
    for t in labelled:
        gaps = []
        for f in range(motion.frame_at(t - 0.03), motion.frame_at(t + 0.03) + 1):
            pos = points + motion.displacement(f) + motion.jaw_offset[f]
            gaps.append(np.nanmin(motion.palate_at(f).clearance(pos[region])[0]))
        touching += min(gaps) <= 0.5e-3
    assert touching >= 8 and len(labelled) == 10


def test_the_humps_keep_the_volume_to_first_order(model):
    """Each hump column's first-order volume change (the volume gradient times the shape) is zero: the rest of
    the surface draws in by what a hump lifts; the kinematic shapes alone change it."""
    from tonguevis.sim.patches import hump_shapes, volume_neutral
    from tonguevis.sim.volume import volume_gradients

    base, nodes, aug, _ = _basis(model)
    m, s = 30, len(nodes)
    points, tets = model.mesh.points, np.asarray(model.mesh.tets)
    gradient = np.zeros((len(points), 3))
    np.add.at(gradient, tets.ravel(), volume_gradients(points, tets).reshape(-1, 3))
    g = gradient.ravel()
    humps = aug.phi[:, m + 3 * s:]
    raw = hump_shapes(points, nodes, base.free_dofs, *aug.info["hump_m"])
    assert np.abs(g @ humps).max() < 1e-12 * np.abs(g @ raw).max()
    assert np.abs(g @ raw).max() > 1e-6  # lifting the tissue alone would change the volume
    neutral = volume_neutral(raw, model, base.free_dofs)
    width = 3 * (1 + HUMP_TILTS)
    for k, node in enumerate(nodes):  # the translations combined to move their own node by the identity
        cols = slice(k * width, k * width + 3)
        at_node = slice(3 * node, 3 * node + 3)
        np.testing.assert_allclose(humps[at_node, cols], np.eye(3), atol=1e-12)
        np.testing.assert_allclose(humps[:, cols], neutral[:, cols] @ np.linalg.inv(neutral[at_node, cols]),
                                   atol=1e-12)
        leans = slice(k * width + 3, (k + 1) * width)
        np.testing.assert_allclose(humps[:, leans], neutral[:, leans], atol=1e-15)



def test_the_projection_equals_its_plain_reference(model):
    """patches_below_palate's frames (the step in the null space, the rows rotated once per pass) equal the plain
    per-frame reference (held_below_reference: the shapes rotated whole, the step recovered by least squares)
    to rounding, on humps raising three sensors 4 mm under a roof that comes down behind them (the dorsum behind the
    hindmost goes through it), warped."""
    from tonguevis.mesh import dorsal_surface_nodes
    from tonguevis.palate import PalateSurface
    from tonguevis.sim.patch_contact import held_below_reference, patches_below_palate
    from tonguevis.sim.patches import patch_costs
    from tonguevis.sim.rotation import accumulated_rotation_matrix

    base, nodes, aug, rotation = _basis(model)
    m, frames = 30, 5
    pts = model.mesh.points
    rng = np.random.default_rng(5)
    q = rng.normal(0, 2e-5, (frames, m))
    measured = np.tile([0.0, 0.0, 4e-3], (frames, len(nodes), 1)) + rng.normal(0, 3e-4, (frames, len(nodes), 3))
    c = close_sensor_gaps(aug, rotation, nodes, q, measured, warping=True)
    full = np.hstack([q, c])
    # a roof 4.3 mm over the highest sensor at the hindmost sensor, coming down behind it (a velum)
    back = pts[nodes, 0].min()
    x, y = np.arange(-0.1, 0.1, 1e-3), np.arange(-0.05, 0.05, 1e-3)
    roof = pts[nodes, 2].max() + 4.3e-3 + 0.4 * np.minimum(x - back, 0.0)
    palate = PalateSurface(x, y, np.tile(roof, (len(y), 1)), metadata={"frame": "model"})
    candidates = dorsal_surface_nodes(model.mesh)
    allowed = np.tile(~np.isin(candidates, nodes), (frames, 1))
    contact = {"points": pts, "palate": palate, "jaw_offset": np.zeros((frames, 3))}
    fast, done = patches_below_palate(full, aug, nodes, contact, candidates, allowed, rotation=rotation)
    assert len(done) >= 3  # the humps went through the palate and were projected

    dofs = (3 * candidates[:, None] + np.arange(3)).ravel()
    phi_modes, phi_patch = aug.phi[dofs, :m], aug.phi[dofs, m:].reshape(len(candidates), 3, -1)
    sensor_dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    null = _null_space(aug.phi[sensor_dofs, m:], patch_costs(aug, nodes))
    for f in range(frames):
        turns = accumulated_rotation_matrix((rotation[dofs, :m] @ q[f]).reshape(-1, 3))
        start = pts[candidates] + np.einsum("kab,kb->ka", turns, (phi_modes @ q[f]).reshape(-1, 3))
        shapes = np.einsum("kab,kbp->kap", turns, phi_patch)
        ref = held_below_reference(null, shapes, start, palate, np.zeros(3), c[f], allowed[f], 1e-4)
        if f in done:
            np.testing.assert_allclose(fast[f, m:], ref, atol=1e-9 * np.abs(ref).max())
        else:
            assert ref is None or np.allclose(ref, c[f])


def test_a_sensor_taken_up_again_starts_where_the_other_humps_put_its_node(model):
    """Around a dropout a sensor's weight w eases its patch in: with humps its node goes from where the others'
    humps put it without it (w = 0) to its own gap (w = 1), w of the way (closing w x its gap pinned it where the
    modes had it, and the overlapping humps jumped: 2.6 mm a frame on the shared /ka/ 006)."""
    base, nodes, aug, rotation = _basis(model)
    m, s = 30, len(nodes)
    rng = np.random.default_rng(4)
    q = np.zeros((3, m))
    measured = rng.normal(0, 2e-3, (3, s, 3))
    weight = np.ones((3, s))
    weight[:, 1] = [0.0, 0.4, 1.0]
    eased = close_sensor_gaps(aug, rotation, nodes, q, measured, warping=False, weight=weight)
    without = measured.copy()
    without[:, 1] = np.nan
    free = close_sensor_gaps(aug, rotation, nodes, q, without, warping=False)
    rows = (3 * nodes[1] + np.arange(3))
    patch = aug.phi[rows, m:]
    there, own = patch @ free.T, measured[:, 1].T  # (3, frames): the node's patch displacement
    for f, w in enumerate(weight[:, 1]):
        np.testing.assert_allclose(patch @ eased[f], w * own[:, f] + (1 - w) * there[:, f], atol=1e-12)
    assert np.abs(there[:, 0]).max() > 1e-4  # the others' humps do move it: the test is not of a node at rest
    for k in (0, 2):  # the other sensors on their gaps whatever the weight
        np.testing.assert_allclose(aug.phi[3 * nodes[k] + np.arange(3), m:] @ eased.T, measured[:, k].T, atol=1e-12)


def test_a_motion_saved_before_the_unit_normalisation_loads_with_its_own_basis(model, demo, tmp_path):
    """A motion saved with humps before commit 42fa05e has patch coordinates on the basis without
    :func:`~tonguevis.sim.patches._unit_at_own_node` (no ``unit_at_node`` in its metadata): it loads on that
    basis and draws the shape it was saved with (on the newer basis the same numbers draw another shape)."""
    import json

    motion = simulate(demo, model, modes=40, humps=True)
    info = motion.metadata["sensor_patches"]
    assert info["unit_at_node"]
    path = tmp_path / "new.npz"
    motion.save(path)
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: np.array(data[k]) for k in data.files}
    meta = json.loads(str(arrays["meta"]))
    # the same shapes written as an older tonguevis wrote them: coordinates on the basis without the normalisation
    m, nodes = info["global_modes"], np.array(info["nodes"])
    base = motion.model.base_model  # the placed tongue
    args = (base, base.basis(m), nodes, 1e-3 * info["radius_mm"], 1e-3 * info["reach_mm"],
            tuple(1e-3 * np.asarray(info["hump_mm"])), info["humped"])
    shapes_new = augmented_basis(*args, unit=True).phi[:, m:]
    shapes_old = augmented_basis(*args, unit=False).phi[:, m:]
    q = arrays["q"].copy()
    q[:, m:] = np.linalg.lstsq(shapes_old, shapes_new @ q[:, m:].T, rcond=None)[0].T
    assert np.abs(q[:, m:] - arrays["q"][:, m:]).max() > 1e-3 * np.abs(arrays["q"][:, m:]).max()
    del meta["metadata"]["sensor_patches"]["unit_at_node"]
    arrays.update(q=q, meta=np.array(json.dumps(meta)))
    old = tmp_path / "old.npz"
    np.savez(old, **arrays)
    again = Motion.load(old)
    for i in (0, 40, len(motion.times) - 1):
        np.testing.assert_allclose(again.displacement(i), motion.displacement(i), atol=1e-9)
