"""The sensor patches kept below the palate: where a hump would push the tongue into the palate, the palate stops it.

The modes are kept below the palate during the dynamics (:mod:`tonguevis.sim.contact`); the sensor patches come
after them (:func:`tonguevis.sim.patches.close_sensor_gaps`), and a hump is broad: at a /k/ closure the dorsum
around the TD coil rises with it, and where the palate comes down behind the coil (the velum, the back of the
vault) the hump would go through it.  Here each frame where it does is projected onto the nearest patch
coordinates, in the patches' own cost metric (:func:`tonguevis.sim.patches.patch_costs`), that keep every sensor
node where the patches put it and every surface node below the palate: the same QP as the contact's
(:func:`tonguevis.sim.contact._active_set`), with the patch coordinates for the modes.  The hump flattens against
the palate and the local shapes hold the sensor: the tongue fills the vault instead of going through it.
"""

from __future__ import annotations

import numpy as np

from tonguevis.sim.contact import BAND, CONFLICT_RADIUS, MARGIN, MAX_PASSES, clearance_at
from tonguevis.sim.least_distance import least_distance as _least_distance
from tonguevis.sim.least_distance_kernel import LeastDistanceBatch
from tonguevis.sim.modal import ModalBasis

#: A closure's pull engaged this far (0-1) has handed its sensors' neighbourhood over to the local shapes.
PULL_HANDOVER = 0.5


def allowed_candidates(contact: dict, conflicts, n_frames: int, candidates: np.ndarray,
                       sensors_free: bool = True) -> np.ndarray:
    """(F, k) bool: which of the ``candidates`` (k,) nodes the palate may hold, frame by frame: all but those
    within :data:`CONFLICT_RADIUS` of a sensor that went above the palate in that frame (``conflicts``: (frame,
    sensor) pairs; the sensor wins there) and the sensor nodes themselves (each is where its sensor is, held
    under the palate by the drive, perhaps nearer than the margin: a constraint of its own beside the equality
    holding it would be infeasible, as it was at the first /k/ closure of the shared 007, TD 0.08 mm under;
    ``sensors_free=False`` keeps them, for the modes' correction, whose sensors are held by springs)."""
    pts, sensors = contact["points"], np.asarray(contact["sensor_nodes"])
    near = np.linalg.norm(pts[candidates][:, None] - pts[sensors][None], axis=2) < CONFLICT_RADIUS
    allowed = np.ones((n_frames, len(candidates)), dtype=bool)
    for f, s in conflicts:
        if f < n_frames and s < near.shape[1]:
            allowed[f] &= ~near[:, s]
    if sensors_free:
        allowed &= ~np.isin(candidates, sensors)[None]
    return allowed


def humps_under_palate(run, q: np.ndarray, contact: dict, schedule: dict) -> np.ndarray:
    """(F, m + p) the modes' coordinates ``q`` (F, m) with the patches' of a run with humps and a palate.

    run : the :class:`~tonguevis.sim.motion_builder.MotionBuilder` (its ``patch_coordinates``, ``basis``,
    ``rotation``, ``model``, ``prep``, ``warping``); schedule : the drive's (``conflicts``; ``pull_weight`` where
    a closure presses the tip).  Where a closure's pull acts the local shapes take over from the humps by its
    engagement (a hump under the blade's coils carried the pressed tip back down with it: on the shared /ta/ 009
    the tip then touched at 1 of 2 closures, 2 without humps); every frame is then kept below the palate
    (:func:`patches_below_palate`, the contact's candidates: the dorsal surface, the pulled nodes included), a
    frame it cannot solve falling back to the local shapes alone.  ``schedule["humps_flattened"]`` says how
    many frames the palate flattened."""
    n = len(q)
    humped = run.patch_coordinates(q, 0, n)
    local = run.patch_coordinates(q, 0, n, local_only=True)
    pull = schedule.get("pull_weight")
    weight = np.zeros(n) if pull is None or np.size(pull) == 0 else np.clip(np.max(pull, axis=1) / PULL_HANDOVER, 0.0, 1.0)[:n]
    coordinates = (1.0 - weight)[:, None] * humped + weight[:, None] * local
    candidates = np.asarray(contact["candidates"], dtype=np.int64)
    # The closures' pulled nodes are held below the palate as every other candidate (not freed as the sensors'
    # nodes are): the modes press them onto it, and the local shapes closing the sensors' gaps on top of that
    # pushed them 0.6-2 mm into it on the shared /ka/ 006 when the pulled frames were left unprojected.
    sensors_only = {**contact, "sensor_nodes": np.asarray(run.prep.nodes)}
    allowed = allowed_candidates(sensors_only, schedule.get("conflicts", []), n, candidates)
    out, flattened = patches_below_palate(np.hstack([q, coordinates]), run.basis, run.prep.nodes, contact,
                                          candidates, allowed, fallback=local,
                                          rotation=run.rotation if run.warping else None)
    schedule["humps_flattened"] = int(len(flattened))
    return out


def patches_below_palate(q: np.ndarray, basis: ModalBasis, nodes: np.ndarray, contact: dict, candidates: np.ndarray,
                         allowed: np.ndarray | None = None, margin: float = MARGIN,
                         fallback: np.ndarray | None = None,
                         rotation: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(q with its patch coordinates projected below the palate (F, m + p), the frames projected).

    q : (F, m + p) the modes' coordinates then the patches' (:func:`~tonguevis.sim.patches.close_sensor_gaps`);
    basis : the augmented basis (``info["global_modes"]`` = m); nodes : (S,) the sensor nodes;
    contact : the run's contact context (points, palate, jaw_offset with the velum's lift);
    candidates : (k,) the nodes kept below the palate; allowed : (F, k) those the palate may hold in each frame
    (:func:`allowed_candidates`; None: all).
    fallback : (F, p) patch coordinates for a frame whose projection finds no shape below the palate (the
    local shapes alone, :func:`~tonguevis.sim.patches.close_sensor_gaps` ``local_only``); None: kept as is.
    rotation : the basis' rotation matrix W (3n, m + p) with warping (None: linear): a node moves by
    R̃_i (Φ_i q + P_i c), R̃_i from the modes alone, so the clearances are those of the shape drawn and still
    linear in the patch coordinates c.  The sensor nodes stay to 1e-9 m.
    """
    from tonguevis._blas import single_threaded_blas
    from tonguevis.sim.contact_kernel import Clearance
    from tonguevis.sim.patches import patch_costs
    from tonguevis.sim.kernels import rotate_accumulated_compiled as rotated

    q = np.array(q, dtype=np.float64, copy=True)
    m = basis.info["global_modes"]
    cand = np.asarray(candidates, dtype=np.int64)
    dofs = (3 * cand[:, None] + np.arange(3)).ravel()
    phi_modes = np.ascontiguousarray(basis.phi[dofs, :m])
    patch_flat = np.ascontiguousarray(basis.phi[dofs, m:])  # (3k, p)
    sensor_dofs = (3 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(3)).ravel()
    rows = basis.phi[sensor_dofs, m:]  # (3S, p)
    cost = patch_costs(basis, nodes)
    query = Clearance(contact["palate"], contact["points"][cand])
    offsets = np.asarray(contact["jaw_offset"])
    w_rows = None if rotation is None else np.ascontiguousarray(rotation[dofs, :m])
    allowed = np.ones((len(q), len(cand)), dtype=bool) if allowed is None else allowed[:len(q)]
    null = _null_space(rows, cost)
    shapes_null = (patch_flat @ null).reshape(len(cand), 3, -1)  # Φ_P N (k, 3, z)
    done = []
    with single_threaded_blas():  # many small products: a threaded BLAS's wake-ups cost more than they do
        for first in range(0, len(q), 256):  # chunks: the rotations of every surface node are 72 bytes a frame
            part = np.arange(first, min(first + 256, len(q)))
            # each frame as the modes and its patch coordinates c0 place it (the patches in the modes' frame)
            moved = ((q[part, :m] @ phi_modes.T) + (q[part, m:] @ patch_flat.T)).reshape(len(part), len(cand), 3)
            turns = None  # the modes' rotation vectors at the candidates (f, k, 3): R̃(w) Φ_P c turns with them
            if w_rows is not None:
                turns = (q[part, :m] @ w_rows.T).reshape(len(part), len(cand), 3)
                moved = rotated(turns, moved)
            gap, _ = query(moved, offsets[part])
            low = np.where(allowed[part] & np.isfinite(gap), gap, np.inf).min(axis=1)
            inside = np.flatnonzero(low < margin - 1e-7)  # the frames that go through the palate
            if len(inside) == 0:
                continue
            chunk = part[inside]
            steps = _held_below(shapes_null, None if turns is None else turns[inside], moved[inside], query,
                                offsets[chunk], allowed[chunk], margin)
            found = np.all(np.isfinite(steps), axis=1)
            q[chunk[found], m:] += steps[found] @ null.T
            done.extend(chunk[found])
            if fallback is not None:
                q[chunk[~found], m:] = fallback[chunk[~found]]
    return q, np.asarray(done, dtype=np.int64)


def _null_space(rows: np.ndarray, cost: np.ndarray) -> np.ndarray:
    """(p, p - r) N with rows @ N = 0 and N^T diag(cost) N = I (r = rank of rows (3S, p))."""
    scale = 1.0 / np.sqrt(cost)
    _, sv, vt = np.linalg.svd(rows * scale, full_matrices=True)
    rank = int(np.sum(sv > sv.max() * 1e-10)) if sv.size else 0
    return scale[:, None] * vt[rank:].T


def _held_below(shapes_null, turns, moved, query, offsets, ok, margin) -> np.ndarray:
    """(f, z) each frame's step z below the palate (NaN: none found within 2 x :data:`MAX_PASSES` passes).

    The nearest patch coordinates to a frame's c0 in the cost metric keeping the sensor nodes are c0 + N z with
    N the sensors' rows' null space (N^T C N = I), so each pass is a least distance problem in z.
    shapes_null : (k, 3, z) Φ_P N, the candidates' patch shapes in the null space (the modes' frame);
    turns : (f, k, 3) the modes' rotation vectors w at the candidates, R̃ = R̃(w) (None: linear); moved : (f, k, 3) the
    candidates' displacements at c0 (rotated), m; query : the candidates'
    :class:`~tonguevis.sim.contact_kernel.Clearance`; offsets : (f, 3|4); ok : (f, k) the candidates the palate
    may hold.  A node at c0 + N z is at its place at c0 plus R̃ Φ_P N z, so its clearance's row is
    (R̃ᵀ n)ᵀ Φ_P N.  The frames take their passes in step (one clearance query a pass for all those still
    going), each its own least distance problems.  Unlike :func:`tonguevis.sim.contact._active_set`, each
    pass keeps every earlier pass's linearisation (cutting planes): a hump moves a wide region under a curved
    palate, and a node linearised at one shape alone sent the next pass elsewhere (passes that oscillated by
    5-10 mm on the shared /ka/ 007).  A pass's problems are solved together, compiled
    (:class:`~tonguevis.sim.least_distance_kernel.LeastDistanceBatch`: Goldfarb-Idnani, each started from the
    frame's answer of the pass before, whose rows are all still there), the NNLS (:func:`_least_distance`)
    taking the few it gives back: the one optimum either way, to rounding (tests/sim/test_least_distance.py).
    :func:`held_below_reference` is one frame's, written out plainly (tests/sim/test_humps.py)."""
    from tonguevis.sim.kernels import rotate_accumulated_compiled as rotated

    n, k = moved.shape[:2]
    width = shapes_null.shape[2]
    flat = shapes_null.reshape(3 * k, width)
    z = np.zeros((n, width))
    out = np.full((n, width), np.nan)
    problems = LeastDistanceBatch(n, width, 2 * MAX_PASSES)  # each frame's rows, and its last answer
    going = np.arange(n)
    for _ in range(2 * MAX_PASSES):
        if len(going) == 0:
            break
        step = (z[going] @ flat.T).reshape(len(going), k, 3)
        if turns is not None:
            step = rotated(turns[going], step)
        gap, normal = query(moved[going] + step, offsets[going], normals=True)
        usable = ok[going] & np.isfinite(gap)
        inside = np.any(usable & (gap < margin - 1e-7), axis=1)
        out[going[~inside]] = z[going[~inside]]
        # clearance(z') ~ gap + n . R̃ Φ_P N (z' - z) >= margin, for every near candidate of every frame inside
        pair_frame, near = np.nonzero(usable & (gap < margin + BAND) & inside[:, None])
        n_own = normal[pair_frame, near]
        if turns is not None:  # R̃ᵀ n = R̃(-w) n (R̃ = I + a[w]× + b[w]×², [w]× antisymmetric)
            n_own = rotated(-turns[going[pair_frame], near], n_own)
        rows = np.einsum("pc,pcz->pz", n_own, shapes_null[near])
        h = margin - gap[pair_frame, near] + np.einsum("pz,pz->p", rows, z[going[pair_frame]])
        frames = going[inside]
        counts = np.bincount(pair_frame, minlength=len(going))[inside]
        problems.add(frames, rows, h, np.concatenate([[0], np.cumsum(counts)]))
        solved = problems.solve(frames)
        z[frames[solved]] = problems.z[frames[solved]]
        still = list(frames[solved])
        for i in frames[~solved]:  # the few the compiled solver gives back: the NNLS
            found = _least_distance(*problems.problem(i))
            if found is not None:
                z[i] = found
                still.append(i)
        going = np.sort(np.asarray(still, dtype=np.int64))
    return out


def held_below_reference(null, phi_patch, points, palate, offset, c0, ok, margin):
    """:func:`_held_below` written out plainly (the reference of tests/sim/test_humps.py): the patch shapes
    ``phi_patch`` (k, 3, p) already rotated, ``points`` (k, 3) the candidates at ``c0`` less its patch part
    (as placed by the modes), the step recovered from c by least squares each pass; returns c or None."""
    c = c0
    g_all, h_all = np.zeros((0, null.shape[1])), np.zeros(0)
    phi_null = np.einsum("kcp,pz->kcz", phi_patch, null)
    for _ in range(2 * MAX_PASSES):
        gap, normal = clearance_at(palate, points + np.einsum("kcp,p->kc", phi_patch, c), offset)
        usable = ok & np.isfinite(gap)
        if not np.any(usable & (gap < margin - 1e-7)):
            return c
        near = np.flatnonzero(usable & (gap < margin + BAND))
        rows = np.einsum("kc,kcz->kz", normal[near], phi_null[near])
        z_now = np.linalg.lstsq(null, c - c0, rcond=None)[0]
        g_all = np.vstack([g_all, rows])
        h_all = np.concatenate([h_all, margin - gap[near] + rows @ z_now])
        z = _least_distance(g_all, h_all)
        if z is None:
            return None
        c = c0 + null @ z
    return None
