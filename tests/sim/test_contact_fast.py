"""The contact's fast path (compiled clearances, the frames in contact solved together) against the reference.

The reference is today's solve (``backend="numpy"``: NumPy clearances, one frame at a time); the
fast path must give the same shapes to 1e-10 relative, the same frames, forces and conflicts,
on the demo /ta/ with the generic palate and on cases with many frames in contact.
"""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.palate import generic_palate

REL = 1e-10


def rel_diff(a: np.ndarray, b: np.ndarray) -> float:
    scale = np.abs(a).max()
    return float(np.abs(a - b).max() / scale) if scale > 0 else float(np.abs(b).max())


def test_the_compiled_clearance_is_the_palates_own():
    """Points inside, below and outside the footprint of a turned, scaled palate: the same gaps
    (NaN outside) and normals as PalateSurface.clearance; also a query large enough to be split
    over threads."""
    from tonguevis.sim.contact_kernel import Clearance

    rng = np.random.default_rng(3)
    turn = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    turn *= np.linalg.det(turn)  # a rotation
    turned = generic_palate().transformed(turn, 0.8, np.array([0.01, -0.02, 0.003]))
    for palate, n_frames in ((generic_palate(), 30), (turned, 30), (turned, 1100)):  # 1100 x 200: threads
        verts, _ = palate.triangles()
        base = rng.uniform(verts.min(axis=0) - 0.005, verts.max(axis=0) + 0.005, size=(200, 3))
        disp = rng.normal(size=(n_frames, 200, 3)) * 3e-3
        offset = rng.normal(size=(n_frames, 3)) * 1e-3
        gap, normal = Clearance(palate, base)(disp, offset, normals=True)
        ref_gap, ref_normal = palate.clearance((base[None] + disp + offset[:, None]).reshape(-1, 3))
        ref_gap, ref_normal = ref_gap.reshape(n_frames, 200), ref_normal.reshape(n_frames, 200, 3)
        inside = np.isfinite(ref_gap)
        assert 0.2 < inside.mean() < 0.9  # both kinds of point are there
        np.testing.assert_array_equal(np.isfinite(gap), inside)
        np.testing.assert_allclose(gap[inside], ref_gap[inside], rtol=0, atol=1e-12)
        np.testing.assert_allclose(normal[inside], ref_normal[inside], rtol=0, atol=1e-12)
        gap_only, none = Clearance(palate, base)(disp, offset)
        assert none is None and np.array_equal(np.isfinite(gap_only), inside)


@pytest.fixture(scope="module")
def demo():
    """The demo /ta/ placed as simulate() places it: model, targets, modes, the contact context."""
    from tonguevis.io import read_recording
    from tonguevis.paths import DATA_DIR
    from tonguevis.sim import TongueModel
    from tonguevis.sim.placement import targets_in_frame
    from tonguevis.sim.simulate import contact_context

    rec = read_recording(DATA_DIR / "spk1_ta.tsv", sensor_map=DATA_DIR / "sensor_map.json").on_uniform_grid()
    model, prep, _ = targets_in_frame(rec, TongueModel.default(), "speaker", "speaker", None, None, tongue_size=1.0)
    basis = model.basis(40)
    dofs = (3 * prep.nodes[:, None] + np.arange(3)).ravel()
    s = len(prep.nodes)
    phi_s = basis.phi[dofs].reshape(s, 3, -1)
    w_s = model.rotation_matrix(basis)[dofs].reshape(s, 3, -1)
    return rec, model, prep, basis, phi_s, w_s, contact_context("generic", prep, model, basis, rec)


def both_backends(demo, palate, sensor_stiffness, drawn=False):
    """The drive (contact solve), the dynamics and the correction after them, on each backend (drawn: the
    correction also of the warped shape drawn, keep_below_palate's rotation rows)."""
    from tonguevis.sim.constrained import point_stiffness
    from tonguevis.sim.newmark import NewmarkSettings
    from tonguevis.sim.newmark_kernel import integrate_compiled
    from tonguevis.sim.simulate import keep_below_palate, drive_schedule

    rec, model, prep, basis, phi_s, w_s, context = demo
    settings = NewmarkSettings(dt=1 / rec.rate, alpha=model.material.alpha, beta=model.material.beta)
    k_ref = point_stiffness(basis.eigenvalues, phi_s)
    base = 0.0 if sensor_stiffness is None else 1.0 / (sensor_stiffness * k_ref)
    out = {}
    for backend in ("numpy", "warp"):
        contact = {**context, "palate": palate, "backend": backend}
        targets, compliance, schedule = drive_schedule(prep.displacement, rec.rate, basis.eigenvalues, phi_s,
                                                       sensor_stiffness, contact=contact)
        if backend == "numpy":  # the same dynamics for both: only the contact differs
            q = integrate_compiled(basis.eigenvalues, phi_s, w_s, targets, settings, compliance=compliance,
                                   external=schedule["external"], rates=False).q
        rows = _candidate_rotation_rows(model, basis, contact) if drawn else None
        corrected, frames = keep_below_palate(q, contact, schedule, basis, phi_s, base, rows)
        out[backend] = targets, schedule, corrected, frames
    return out["numpy"], out["warp"]


def _candidate_rotation_rows(model, basis, contact):
    dofs = (3 * np.asarray(contact["candidates"])[:, None] + np.arange(3)).ravel()
    return model.rotation_matrix(basis)[dofs]


def _drawn_gaps(demo, palate, q):
    """(F, k) the candidates' clearances as drawn (modal warping: R̃(Wq) Φq)."""
    from tonguevis.sim.contact import clearance_at
    from tonguevis.sim.rotation import rotate_accumulated

    rec, model, prep, basis, phi_s, w_s, context = demo
    cand = np.asarray(context["candidates"])
    rows = _candidate_rotation_rows(model, basis, context)
    k = len(cand)
    d = (q @ context["phi_nodes"].reshape(3 * k, -1).T).reshape(len(q), k, 3)
    drawn = rotate_accumulated((q @ rows.T).reshape(len(q), k, 3), d)
    return clearance_at(palate, model.mesh.points[cand][None] + drawn, context["jaw_offset"])[0]


def assert_same(ref, fast):
    targets, schedule, corrected, frames = ref
    f_targets, f_schedule, f_corrected, f_frames = fast
    assert np.array_equal(np.isnan(targets), np.isnan(f_targets))
    assert rel_diff(np.nan_to_num(targets), np.nan_to_num(f_targets)) < REL
    assert rel_diff(schedule["external"], f_schedule["external"]) < REL
    assert np.array_equal(schedule["active"], f_schedule["active"])
    assert schedule["conflicts"] == f_schedule["conflicts"]
    np.testing.assert_array_equal(frames, f_frames)
    assert rel_diff(corrected, f_corrected) < REL


def test_the_demo_with_the_generic_palate_is_solved_as_the_reference_does(demo):
    """Hard sensors (the paper's setting): the tongue presses on the generic palate in a few frames."""
    ref, fast = both_backends(demo, demo[-1]["palate"], None)
    assert np.sum(ref[1]["active"] > 0) > 0  # frames with contact forces: the solve has work to do
    assert_same(ref, fast)


def test_many_frames_in_contact_are_solved_as_the_reference_does(demo):
    """The generic palate 6 mm lower: the tongue presses on it in 163 frames, the tip sensor goes
    above it (138 conflicts), and the dynamics carry the tongue into it (178 frames corrected)."""
    low = demo[-1]["palate"].transformed(np.eye(3), 1.0, np.array([0.0, 0.0, -0.006]))
    ref, fast = both_backends(demo, low, 20.0)
    assert np.sum(ref[1]["active"] > 0) > 100 and len(ref[1]["conflicts"]) > 100 and len(ref[3]) > 100
    assert_same(ref, fast)


def test_the_drawn_shape_is_corrected_as_the_reference_does(demo):
    """The correction held to the warped shape drawn (keep_below_palate's rotation rows, the rotation's part
    held fixed: correct_frames' shift) gives the same on both backends, and it does correct: frames the linear
    correction left in as drawn are moved, and their drawn shape goes less deep."""
    low = demo[-1]["palate"].transformed(np.eye(3), 1.0, np.array([0.0, 0.0, -0.006]))
    ref, fast = both_backends(demo, low, None, drawn=True)
    assert_same(ref, fast)
    linear = both_backends(demo, low, None)[0]
    moved = np.flatnonzero(np.any(ref[2] != linear[2], axis=1))
    assert len(moved) > 20
    from tonguevis.sim.patch_contact import allowed_candidates

    context = demo[-1]
    held = allowed_candidates(context, ref[1]["conflicts"], len(ref[2]), np.asarray(context["candidates"]),
                              sensors_free=False)[moved]  # as the correction counts them
    before = np.nanmin(np.where(held, _drawn_gaps(demo, low, linear[2])[moved], np.nan), axis=1)
    after = np.nanmin(np.where(held, _drawn_gaps(demo, low, ref[2])[moved], np.nan), axis=1)
    assert np.all(after > before)


def test_a_palate_the_tongue_never_reaches_costs_no_solve(demo):
    """The demo on 40 modes with its springs stays below the generic palate: no frame to solve in
    either stage (the fast path's empty cases), nothing in contact."""
    from tonguevis.sim import simulate

    held = simulate(demo[0], modes=40, palate="generic", closures=False)  # the closures would press the tip on it
    c = held.metadata["contact"]
    assert c["frames_with_contact_forces"] == 0 and c["frames_corrected_after_the_dynamics"] == 0
    assert held.penetration.max() == 0 and held.contact_area.max() == 0


def test_simulate_reports_the_same_contact_on_both_backends(demo):
    """The whole run against the generic palate 4 mm lower (still the model's frame: used as is):
    the contact's figures of simulate() are the reference's to rounding."""
    from tonguevis.sim import simulate

    low = generic_palate().transformed(np.eye(3), 1.0, np.array([0.0, 0.0, -0.004]))
    low.metadata.update(generic_palate().metadata)
    rec = demo[0]
    runs = [simulate(rec, modes=40, palate=low, backend=b) for b in ("numpy", "warp")]
    ref, fast = (r.metadata["contact"] for r in runs)
    assert ref["frames_with_contact_forces"] > 20 and ref["frames_in_contact"] > 20
    for key in ("frames_in_contact", "frames_with_contact_forces", "frames_corrected_after_the_dynamics",
                "sensors_above_palate", "conflicts"):
        assert ref[key] == fast[key]
    for key in ("penetration_max_mm", "contact_area_max_mm2"):
        assert fast[key] == pytest.approx(ref[key], rel=1e-6, abs=1e-9)
    np.testing.assert_allclose(runs[1].penetration, runs[0].penetration, rtol=0, atol=1e-9)
    np.testing.assert_allclose(runs[1].contact_area, runs[0].contact_area, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("workers", [1, 3])
def test_compiled_contact_figures_equal_the_reference(demo, workers):
    """frame_figures on the compiled backend with a palate measures contact on the candidate nodes
    alone: the same penetration and contact area as the NumPy path over the whole surface (with
    conflicts excluded), the volume and far field as without a palate (float32 products, 1e-8)."""
    from tonguevis.sim.figures import ContactProbe, frame_figures
    from tonguevis.sim.newmark import NewmarkSettings
    from tonguevis.sim.newmark_kernel import integrate_compiled
    from tonguevis.sim.simulate import drive_schedule

    rec, model, prep, basis, phi_s, w_s, context = demo
    low = context["palate"].transformed(np.eye(3), 1.0, np.array([0.0, 0.0, -0.004]))
    targets, compliance, _ = drive_schedule(prep.displacement, rec.rate, basis.eigenvalues, phi_s, 20.0)
    settings = NewmarkSettings(dt=1 / rec.rate, alpha=model.material.alpha, beta=model.material.beta)
    q = integrate_compiled(basis.eigenvalues, phi_s, w_s, targets, settings, compliance=compliance, rates=False).q
    candidates = np.asarray(model.dorsal_nodes)  # no palate in the dynamics: the tongue goes into the low one
    rng = np.random.default_rng(5)
    conflicts = np.column_stack([rng.integers(0, len(q), 40), rng.integers(0, len(prep.nodes), 40)])
    near = rng.random((len(candidates), len(prep.nodes))) < 0.2
    probe = ContactProbe(model.mesh.points, candidates, low, prep.jaw_offset, model.surface_faces, conflicts, near)
    ref = frame_figures(model, q, True, "numpy", contact=probe, chunk=300, workers=workers)
    fast = frame_figures(model, q, True, "warp", contact=probe, chunk=300, workers=workers)
    assert ref.penetration.max() > 1e-3 and (ref.contact_area > 0).sum() > 20  # contact to compare
    np.testing.assert_allclose(fast.penetration, ref.penetration, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.contact_area, ref.contact_area, rtol=1e-10, atol=1e-16)
    np.testing.assert_allclose(fast.volume_change, ref.volume_change, rtol=0, atol=1e-8)
    np.testing.assert_allclose(fast.largest_displacement, ref.largest_displacement, rtol=0, atol=1e-8)


def test_the_height_field_of_a_mesh_is_the_lowest_triangle_over_each_grid_point():
    """palate._height_field (all triangles' boxes at once) against the plain loop over triangles it
    replaced, on a folded random surface (overlapping triangles: the lowest wins), bit for bit."""
    from tonguevis.palate import _height_field

    rng = np.random.default_rng(7)
    gx, gy = np.meshgrid(np.linspace(0, 0.03, 13), np.linspace(-0.01, 0.012, 9))
    pts = np.column_stack([gx.ravel(), gy.ravel(), 0.01 + 2e-3 * rng.normal(size=gx.size)])
    pts[:, :2] += rng.normal(size=(len(pts), 2)) * 1e-3  # triangles overlap seen from below
    ids = np.arange(gx.size).reshape(gx.shape)
    quads = np.stack([ids[:-1, :-1], ids[:-1, 1:], ids[1:, 1:], ids[1:, :-1]], axis=-1).reshape(-1, 4)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]], [[0, 0, 1]]])  # and a degenerate one
    step = 1e-3
    fast = _height_field(pts, tris, step, {})
    x, y = fast.x, fast.y
    z = np.full((len(y), len(x)), np.inf)
    lo = pts[:, :2].min(axis=0)
    for t in tris:
        a, b, c = pts[t]
        v0, v1 = b[:2] - a[:2], c[:2] - a[:2]
        den = v0[0] * v1[1] - v0[1] * v1[0]
        if abs(den) < 1e-18:
            continue
        box_lo = np.minimum(np.minimum(a[:2], b[:2]), c[:2])
        box_hi = np.maximum(np.maximum(a[:2], b[:2]), c[:2])
        i0, j0 = np.maximum(np.ceil((box_lo - lo) / step - 1e-9).astype(int), 0)
        i1, j1 = np.minimum(np.floor((box_hi - lo) / step + 1e-9).astype(int), [len(x) - 1, len(y) - 1])
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                wx, wy = x[i] - a[0], y[j] - a[1]
                u = (wx * v1[1] - wy * v1[0]) / den
                v = (v0[0] * wy - v0[1] * wx) / den
                if u >= -1e-9 and v >= -1e-9 and u + v <= 1 + 1e-9:
                    z[j, i] = min(z[j, i], a[2] + u * (b[2] - a[2]) + v * (c[2] - a[2]))
    z = np.where(np.isfinite(z), z, np.nan)
    assert np.isfinite(z).mean() > 0.5
    np.testing.assert_array_equal(fast.z, z)


def test_contact_area_is_the_surface_the_touching_nodes_stand_for():
    """A node inside the palate or within TOUCH of it brings its share of the surface, however large the
    triangles (a tongue placed at 1.6 times the model read 0 mm² while pressing into the palate)."""
    from tonguevis.palate import PalateSurface
    from tonguevis.sim.contact import TOUCH, contact_frames, node_areas

    # Two 10 mm triangles in a square under a flat roof at z = 0; one corner pushed up into it.
    points = np.array([[0, 0, -1e-3], [1e-2, 0, -1e-3], [0, 1e-2, -1e-3], [1e-2, 1e-2, -1e-3]])
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    areas = node_areas(points, faces)
    assert areas.sum() == pytest.approx(1e-4) and areas[0] == pytest.approx(1e-4 / 6)
    roof = PalateSurface(np.array([-0.01, 0.03]), np.array([-0.01, 0.03]), np.zeros((2, 2)))
    push = np.zeros((3, 4, 3))
    push[1, 0, 2] = 1.5e-3  # node 0 0.5 mm inside
    push[2, :, 2] = 1e-3 - TOUCH / 2  # every node within TOUCH below the roof
    pen, area = contact_frames(push, points, np.arange(4), roof, np.zeros((3, 3)), faces)
    assert pen[0] == 0 and area[0] == 0
    assert pen[1] == pytest.approx(5e-4) and area[1] == pytest.approx(areas[0])  # one node: its share
    assert pen[2] == 0 and area[2] == pytest.approx(1e-4)  # all touching: the whole square


@pytest.fixture(scope="module")
def first_passes(demo):
    """Every frame's first QP pass on the demo against the generic palate 6 mm lower (all sensors held):
    (the sensors' operator, phi_nodes, q0 (F, m), gap (F, k), normal (F, k, 3), ok (F, k)) of the frames with a candidate
    inside the margin, (2, F) bool: whether each frame's QP is well posed (the active block's condition
    number below 1e4, no force below 1e-4 of the largest, no other near candidate within 1e-4 of the
    largest |residual| of the margin) and whether it is ambiguous (condition number above 1e8 or a
    force below 1e-8 of the largest), and the reference's pass of each (NNLS: λ > 0, their candidates, q)."""
    from tonguevis.sim.contact import BAND, MARGIN, _contact_pass_fast, _contact_response, sensor_operator
    from tonguevis.sim.contact_kernel import Clearance

    rec, model, prep, basis, phi_s, w_s, context = demo
    low = context["palate"].transformed(np.eye(3), 1.0, np.array([0.0, 0.0, -0.006]))
    lam = basis.eigenvalues
    P = phi_s.reshape(-1, len(lam))
    gram = (P / lam) @ P.T
    operator = sensor_operator(lam, P, gram, np.zeros(len(P)), np.ones(len(P), bool))
    measured = np.all(np.isfinite(prep.displacement.reshape(len(prep.displacement), -1)), axis=1)
    targets = prep.displacement[measured].reshape(int(measured.sum()), -1)
    q0 = (np.linalg.solve(gram, targets.T).T @ P) / lam  # the sensors where measured, least elastic energy
    phi_nodes = context["phi_nodes"]
    cand = context["points"][context["candidates"]]
    offset = context["jaw_offset"][measured]
    gap, normal = Clearance(low, cand)((q0 @ phi_nodes.reshape(-1, len(lam)).T).reshape(len(q0), -1, 3), offset,
                                      normals=True)
    frames = np.flatnonzero(np.any(gap < MARGIN - 1e-7, axis=1))
    q0, gap, normal = q0[frames], gap[frames], normal[frames]
    ok = np.isfinite(gap)
    ref, posed = [], []
    for j in range(len(frames)):
        lam_a, rows, q = _contact_pass_fast(operator, phi_nodes, q0[j], q0[j], gap[j], normal[j], ok[j], MARGIN)
        near = np.flatnonzero(ok[j] & (gap[j] < MARGIN + BAND))
        on = lam_a > 0
        ref.append((lam_a[on], near[on], q))
        m_mat = _contact_response(rows, operator)[0]
        r = gap[j, near] - MARGIN
        eig = np.linalg.eigvalsh(m_mat[np.ix_(on, on)])
        w = (m_mat @ lam_a + r)[~on]
        posed.append((eig[0] > 1e-4 * eig[-1] and lam_a[on].min() > 1e-4 * lam_a.max()
                      and (w.min(initial=np.inf) > 1e-4 * np.abs(r).max()),
                      eig[0] < 1e-8 * eig[-1] or lam_a[on].min() < 1e-8 * lam_a.max()))
    return operator, phi_nodes, q0, gap, normal, ok, np.array(posed).T, ref


def guessed(first_passes, stale):
    """_guessed_passes on every frame of ``first_passes`` at once, each starting from the active set
    ``stale`` (F, k) bool: (done (F,), q (F, m), λ per frame (its positive ones), support (F, k))."""
    from tonguevis.sim.contact import MARGIN, _guessed_passes

    operator, phi_nodes, q0, gap, normal, ok = first_passes[:6]
    n = len(q0)
    q, forces, external = q0.copy(), stale.astype(np.float64), np.zeros_like(q0)
    done = _guessed_passes([operator] * n, np.arange(n), phi_nodes, q, q0, gap, normal, ok, MARGIN, forces, external)
    return done, q, [f[f > 0] for f in forces], forces > 0


def true_sets(first_passes) -> np.ndarray:
    """(F, k) bool: each frame's active set in the reference's pass."""
    truth = np.zeros(first_passes[3].shape, bool)
    for j, (_, nodes, _) in enumerate(first_passes[-1]):
        truth[j, nodes] = True
    return truth


def test_a_guessed_active_set_gives_the_references_pass(first_passes):
    """Each frame's first pass started from the active set of the frame 5 before it (the warm start a
    stale guess gives where contact moved, was released or began between frames): the frames the
    guess solves get the NNLS pass's q, λ and active set to 1e-10; nine in ten of the well-posed ones are
    solved so (the others: sets of three the corrections do not reach), and none of the ambiguous ones
    (near-duplicate rows pressing with forces 1e-10 of the largest: which of them NNLS keeps is its
    rounding's choice), which the NNLS takes instead."""
    (posed, ambiguous), ref = first_passes[-2], first_passes[-1]
    truth = true_sets(first_passes)
    stale = np.roll(truth, 5, axis=0)
    wrong = np.any(stale != truth, axis=1)
    released = np.any(stale & ~truth, axis=1)  # a node pressed 5 frames before, free now
    assert wrong.sum() > 100 and released.sum() > 50 and posed.sum() > 250 and ambiguous.sum() > 50
    done, q, lams, support = guessed(first_passes, stale)
    assert done[posed].mean() > 0.9 and not done[ambiguous].any()
    assert done[wrong & released].sum() > 30  # wrong guesses corrected, not just given up
    for j in np.flatnonzero(done):
        lam_ref, nodes, q_ref = ref[j]
        np.testing.assert_array_equal(np.flatnonzero(support[j]), nodes)
        assert rel_diff(q_ref, q[j]) < REL and rel_diff(lam_ref, lams[j]) < REL


def test_a_wrong_active_set_is_never_taken(first_passes, monkeypatch):
    """One guess, no correction: a guess that is not the frame's active set (the one of 5 frames
    before where it differs; the right one with a near candidate added or an active one taken out)
    is refused, every time; the right one is taken in every well-posed frame."""
    from tonguevis.sim import contact

    monkeypatch.setattr(contact, "GUESS_ROUNDS", 1)
    posed = first_passes[-2][0]
    truth = true_sets(first_passes)
    near = first_passes[5] & (first_passes[3] < contact.MARGIN + contact.BAND)
    rng = np.random.default_rng(11)
    extra, fewer = truth.copy(), truth.copy()
    for j in range(len(truth)):
        free = np.flatnonzero(near[j] & ~truth[j])
        if len(free):
            extra[j, rng.choice(free)] = True
        if truth[j].sum() > 1:
            fewer[j, rng.choice(np.flatnonzero(truth[j]))] = False
    for stale in (np.roll(truth, 5, axis=0), extra, fewer):
        stale = stale & near  # (as the guess is made; no guess left: the deepest node is the guess)
        wrong = np.any(stale != truth, axis=1) & stale.any(axis=1)
        assert wrong.sum() > 50
        done, *_ = guessed(first_passes, stale)
        assert not done[wrong].any()
    done, q, lams, support = guessed(first_passes, truth)
    assert done[posed].all() and np.array_equal(support[done], truth[done])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["009_OSN12_Tah_withFb_natural_HR.tsv", "006_OSN12_Kah_nofb_natural_take2_HR.tsv"])
def test_real_speech_on_the_speakers_palate_is_solved_as_the_reference_does(name, monkeypatch):
    """Opti-Speech /ta/ 009 and /ka/ 006 against the palate fitted from the speaker's traces (002-004),
    hundreds of frames in contact: simulate() with the contact on its NumPy reference and on the fast
    path (guessed active sets) gives the same q to 1e-10 and the same contact figures.  Skips
    without ../shared."""
    from tests.conftest import shared_file
    from tonguevis.io import read_recording
    from tonguevis.sim import TongueModel, contact, simulate
    from tonguevis.workflows.palate import palate_from_traces

    traces = [shared_file("ema", "optispeech", f) for f in (
        "002_OSN12_Palate_MidSagital_HR.tsv", "003_OSN12_Palate_Coronal_HR.tsv", "004_OSN12_Palate_Scribble_HR.tsv")]
    rec = read_recording(shared_file("ema", "optispeech", name))
    palate, model = palate_from_traces(traces), TongueModel.default()
    fast = simulate(rec, model, palate=palate)
    on_numpy = []
    for solve in ("solve_contact", "correct_frames"):
        def reference(*a, _f=getattr(contact, solve), **k):
            on_numpy.append(_f)
            return _f(*a, **{**k, "backend": "numpy"})
        monkeypatch.setattr(contact, solve, reference)
    ref = simulate(rec, model, palate=palate)
    # both stages on the reference (the correction also for the drawn shape: keep_below_palate's warping rounds)
    assert {f.__name__ for f in on_numpy} == {"solve_contact", "correct_frames"}
    c, r = fast.metadata["contact"], ref.metadata["contact"]
    assert r["frames_with_contact_forces"] > 200 and r["frames_corrected_after_the_dynamics"] > 200
    for key in ("frames_in_contact", "frames_with_contact_forces", "frames_corrected_after_the_dynamics",
                "sensors_above_palate", "conflicts"):
        assert c[key] == r[key]
    assert rel_diff(ref.q, fast.q) < REL


def test_the_contact_response_keeps_its_digits_where_the_sensors_nearly_hold_a_node(demo):
    """M = -AKAᵀ (K: a contact force's move with the hard sensors re-balanced) of rows at the candidates
    nearest the sensors, where M is a small remainder of AΛ⁻¹Aᵀ: _contact_response's M within 1e-12 of
    the exact one (40 digits), where forming -AKAᵀ directly was off by up to 1e-10 and more; and its
    B = KAᵀ moves no sensor."""
    mp = pytest.importorskip("mpmath")
    from tonguevis.sim.contact import _contact_response, sensor_operator

    rec, model, prep, basis, phi_s, w_s, context = demo
    lam = basis.eigenvalues
    P = phi_s.reshape(-1, len(lam))
    operator = sensor_operator(lam, P, (P / lam) @ P.T, np.zeros(len(P)), np.ones(len(P), bool))
    cand = context["points"][context["candidates"]]
    sensors = context["points"][context["sensor_nodes"]]
    nearest = np.argsort(np.linalg.norm(cand[:, None] - sensors[None], axis=2).min(axis=1))[:8]
    normal = np.random.default_rng(5).normal(size=(len(nearest), 3))
    a_rows = -np.einsum("kc,kcm->km", normal / np.linalg.norm(normal, axis=1)[:, None], context["phi_nodes"][nearest])
    m_mat, b_mat = _contact_response(a_rows, operator)
    mp.mp.dps = 40
    a_m, p_m = mp.matrix(a_rows.tolist()), mp.matrix(P.tolist())
    inv_lam = mp.diag([1 / mp.mpf(float(x)) for x in lam])
    y = a_m * inv_lam * p_m.T
    exact = a_m * inv_lam * a_m.T - y * (p_m * inv_lam * p_m.T) ** -1 * y.T
    exact = np.array(exact.tolist(), dtype=float)
    held = np.diag(exact) / np.einsum("km,km->k", a_rows / lam, a_rows)
    assert held.min() < 1e-3  # the sensors hold these nodes: M a small remainder
    assert np.abs(m_mat - exact).max() < 1e-12 * np.abs(exact).max()
    assert np.abs(P @ b_mat).max() < 1e-12 * np.abs(P).max() * np.abs(b_mat).max()
