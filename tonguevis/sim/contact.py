"""Tongue-palate contact: the tongue surface stays below the palate, the sensors win conflicts.

Contact is solved where the sensor targets are: in the static projection of
the targets onto the tongue's deformations (see
:func:`tonguevis.sim.simulate.drive_schedule`).  Per frame, with the sensors
as springs of compliance C (0 = hard),

    min ½ qᵀΛq + Σ_s |Φ_s q - c_s|² / 2C_s   subject to   clearance_i(q) >= margin

for the candidate surface nodes i (upward-facing, the ones that can meet the
palate), clearance being the node's signed distance below the palate
(:meth:`tonguevis.palate.PalateSurface.clearance`, with the palate carried by
the jaw's motion into the jaw's frame the tongue is simulated in, its velum lifted
frame by frame: every ``jaw_offset`` here is (F, 3), or (F, 4) with the lift, :func:`palate_offsets`).  An active
set on the linearised clearances, in force form: q = Λ⁻¹(Φ_sᵀμ - Aᵀλ) with the
sensor forces μ and contact forces λ >= 0, re-linearised after each pass.
The contact forces -Aᵀλ are then applied as external modal forces in the
dynamic solve, whose hard sensor targets are the contact solution's sensor
positions: in the static limit it reproduces the contact solution exactly.

Where a sensor itself lies above the palate (noise, alignment), the sensor
wins: nodes within ``CONFLICT_RADIUS`` of its node get no contact constraint
in that frame, and the conflict is reported.

Two paths give the same solution to rounding (tests/sim/test_contact_fast.py:
1e-10 relative): ``backend="numpy"``, the reference, a frame at a time with
NumPy clearances (:func:`_active_set`); ``"warp"`` (the default), every
frame's clearances in one compiled pass (:mod:`tonguevis.sim.contact_kernel`),
the active set only in the frames where a candidate it may constrain is inside
the margin, those frames' passes in step (one compiled query a pass), the
sensors' elimination by its factors per sensor pattern (:class:`SensorOperator`), and
each pass's QP solved for all those frames at once from a guessed active set
(the frame's set after its last pass, else its deepest node), taken only where
it provably is the QP's one solution, corrected a few times where it is not
(:func:`_guessed_passes`); the frames left (ill-conditioned or ambiguous sets:
near-duplicate rows) get the reference's NNLS, its small solves by LAPACK
directly.  On the Opti-Speech /ka/ 006 against the speaker's palate the NNLS
took 2,594 passes of about 0.1 ms each (a warp kernel for them ran slower: warp's
CPU code manages some 0.3 GFMA/s on these indexed loops); the guesses now take
all of them, and what bounds the fast path is the clearance queries and the
whole-array work around them (scripts/bench_simulation.py).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tonguevis._backend import check_backend

MARGIN = 1e-4  # m: clearance the solve keeps, so that warping's small rotations do not cross the palate
CONFLICT_RADIUS = 10e-3  # m: nodes this close to a sensor above the palate are left to that sensor
#: m: a sensor is above the palate (and wins) only by more than this: the NDI Wave's stated accuracy.  Closer,
#: the contact keeps its neighbourhood below the palate and the sensor's spring gives (a misfit of less than it).
CONFLICT_TOLERANCE = 0.5e-3
MAX_PASSES = 8
BAND = 2e-3  # m: candidates this close to the margin join each pass's linearisation


def palate_offsets(jaw_offset: np.ndarray, lift: np.ndarray | None = None) -> np.ndarray:
    """(F, 4) per frame: the jaw's translation (m, carrying the tongue into the palate's frame) and the velum's
    lift (m; :mod:`tonguevis.sim.speaker_palate`), what every function here takes as ``jaw_offset``
    ((F, 3) alone: a rigid palate)."""
    jaw = np.asarray(jaw_offset, dtype=np.float64).reshape(-1, 3)
    lift = np.zeros(len(jaw)) if lift is None else np.asarray(lift, dtype=np.float64).reshape(-1)
    return np.column_stack([jaw, lift])


def clearance_at(palate, points: np.ndarray, offset: np.ndarray):
    """:meth:`~tonguevis.palate.PalateSurface.clearance` of the tongue's ``points`` (k, 3) in one frame whose
    ``offset`` is (3,) or (4,), or (F, k, 3) in F frames with offsets (F, 3) or (F, 4) (:func:`palate_offsets`):
    (gap, normal) shaped as the points' leading axes."""
    points = np.asarray(points, dtype=np.float64)
    offset = np.asarray(offset, dtype=np.float64)
    shape = points.shape[:-1]
    if offset.ndim == 1:
        moved = points + offset[:3]
        lift = offset[3] if len(offset) > 3 else None
    else:
        moved = points + offset[:, None, :3]
        lift = np.repeat(offset[:, 3], points.shape[1]) if offset.shape[1] > 3 else None
    gap, normal = palate.clearance(moved.reshape(-1, 3), lift=lift)
    return gap.reshape(shape), normal.reshape(*shape, 3)


def solve_contact(eigenvalues, phi_nodes, phi_s, targets, compliance, points, sensor_nodes, candidates, palate,
                  jaw_offset, margin: float = MARGIN, backend: str = "warp"):
    """Contact-aware static solution per frame.

    eigenvalues : (m,); phi_nodes : (k, 3, m) rows of Φ at the candidate nodes;
    phi_s : (S, 3, m); targets : (F, S, 3) m (NaN = not acting); compliance :
    (F, S) m/N; points : (n, 3) rest positions; sensor_nodes : (S,);
    candidates : (k,) node ids; palate : a PalateSurface in the model frame;
    jaw_offset : (F, 3) the jaw's translation (the palate moves by minus it
    in the jaw's frame).
    Returns {"targets": (F, S, 3) sensor-node displacements of the solution (for
    the sensors not acting too: where the others put them),
    "external": (F, m) contact forces in modal space, "active": (F,) contact
    constraints per frame, "conflicts": [(frame, sensor index)]}.
    backend : "warp" (default) queries the clearances of every frame in one compiled pass
    (:mod:`tonguevis.sim.contact_kernel`) and solves only the frames where a candidate the
    solve may constrain is inside the margin; "numpy" is the reference (the same solution to
    rounding: tests/sim/test_contact_fast.py).
    """
    if check_backend(backend) == "warp":
        from tonguevis._blas import single_threaded_blas

        with single_threaded_blas():  # many small products: a threaded BLAS's wake-ups cost more than they do
            return _solve_contact(eigenvalues, phi_nodes, phi_s, targets, compliance, points, sensor_nodes,
                                  candidates, palate, jaw_offset, margin, backend)
    return _solve_contact(eigenvalues, phi_nodes, phi_s, targets, compliance, points, sensor_nodes, candidates,
                          palate, jaw_offset, margin, backend)


def _solve_contact(eigenvalues, phi_nodes, phi_s, targets, compliance, points, sensor_nodes, candidates, palate,
                   jaw_offset, margin, backend):
    """:func:`solve_contact`, on the BLAS threads the caller set."""
    lam = np.asarray(eigenvalues, dtype=np.float64)
    n_frames, n_s, _ = targets.shape
    m = len(lam)
    P = phi_s.reshape(3 * n_s, m)
    gram = (P / lam) @ P.T
    comp3 = np.repeat(np.asarray(compliance, dtype=np.float64), 3, axis=1)
    c_all = targets.reshape(n_frames, 3 * n_s)
    acting = np.repeat(np.all(np.isfinite(targets), axis=2) & np.isfinite(compliance), 3, axis=1)
    # Unconstrained solution of every frame at once (as compliant_targets).
    mats = np.where(acting[:, :, None] & acting[:, None, :], gram[None], 0.0)
    idx = np.arange(3 * n_s)
    mats[:, idx, idx] += np.where(acting, np.where(np.isfinite(comp3), comp3, 0.0), 1.0)
    mult = np.linalg.solve(mats, np.where(acting, c_all, 0.0)[:, :, None])[:, :, 0]
    q_all = (mult @ P) / lam  # (F, m)
    cand_pts = points[candidates]
    out_targets = (q_all @ P.T).reshape(targets.shape)
    external = np.zeros((n_frames, m))
    active_count = np.zeros(n_frames, dtype=np.int64)
    conflicts: list[tuple[int, int]] = []
    near_sensor = np.linalg.norm(cand_pts[:, None] - points[sensor_nodes][None], axis=2) < CONFLICT_RADIUS  # (k, S)
    if backend == "warp":
        _solve_frames_fast(lam, P, gram, phi_nodes, cand_pts, palate, jaw_offset, c_all, comp3, acting, q_all,
                           targets, points[sensor_nodes], near_sensor, margin, out_targets, external,
                           active_count, conflicts)
        return {"targets": out_targets, "external": external, "active": active_count, "conflicts": conflicts}
    u = np.einsum("kcm,fm->fkc", phi_nodes, q_all)
    gap, _ = clearance_at(palate, cand_pts[None] + u, jaw_offset)
    # Sensors above the palate: their neighbourhoods are left to them.
    sensor_gap, _ = clearance_at(palate, points[sensor_nodes][None] + np.nan_to_num(targets), jaw_offset)
    for f in np.flatnonzero(np.nanmin(np.where(np.isfinite(gap), gap, np.inf), axis=1) < margin):
        above = np.flatnonzero((sensor_gap[f] < -CONFLICT_TOLERANCE) & np.all(np.isfinite(targets[f]), axis=1))
        conflicts.extend((int(f), int(s)) for s in above)
        allowed = ~near_sensor[:, above].any(axis=1) if len(above) else np.ones(len(candidates), bool)
        q, lam_f, rows = _active_set(lam, P, gram, phi_nodes, cand_pts, palate, jaw_offset[f], c_all[f],
                                     comp3[f], acting[f], q_all[f], allowed, margin)
        if rows is None:
            continue
        external[f] = -(rows.T @ lam_f)
        active_count[f] = len(lam_f)
        out_targets[f] = (P @ q).reshape(n_s, 3)
    return {"targets": out_targets, "external": external, "active": active_count, "conflicts": conflicts}


def _active_set(lam, P, gram, phi_nodes, cand_pts, palate, offset, c, comp, acting, q0, allowed, margin):
    """One frame's contact solution: (q, contact forces λ (a,), their rows A (a, m)) or (q0, None, None).

    Each pass linearises the clearance of the candidates near the palate
    (within ``BAND`` of the margin) at the current shape and solves the
    resulting QP exactly: the sensors eliminated, q(λ) = q₀ + Bλ, and the
    contact forces the non-negative least-squares solution of the equivalent
    bound-constrained problem (SciPy's NNLS), so λ >= 0 and complementarity
    hold by construction.  Passes repeat until no candidate is closer than
    the margin (the palate is curved), at most MAX_PASSES.
    """
    operator = sensor_operator(lam, P, gram, comp, acting)
    q, lam_a, rows = q0, None, None
    for _ in range(MAX_PASSES):
        u = np.einsum("kcm,m->kc", phi_nodes, q)
        gap, normal = clearance_at(palate, cand_pts + u, offset)
        ok = allowed & np.isfinite(gap)
        if not np.any(ok & (gap < margin - 1e-7)):
            break
        lam_a, rows, q = _contact_pass(operator, phi_nodes, q, q0, gap, normal, ok, margin)
    if lam_a is None or not np.any(lam_a > 0):
        return q0, None, None
    # A contact push moves the surface about as far as it was inside the palate: a solve that moves it
    # much further has failed (near-singular rows), and the frame keeps its contact-free shape.
    u0 = np.einsum("kcm,m->kc", phi_nodes[allowed], q0)
    depth = max(0.0, -float(np.nanmin(clearance_at(palate, cand_pts[allowed] + u0, offset)[0])))
    moved = float(np.abs(np.einsum("kcm,m->kc", phi_nodes[allowed], q - q0)).max())
    if not np.isfinite(moved) or moved > 2 * depth + 2e-3:
        return q0, None, None
    used = lam_a > 0
    return q, lam_a[used], rows[used]


def _contact_pass(operator, phi_nodes, q, q0, gap, normal, ok, margin):
    """One pass of :func:`_active_set`: the QP linearised at ``q`` (the clearances ``gap`` (k,) and
    ``normal`` (k, 3) there; ok : (k,) the candidates that may get a constraint) solved exactly, with
    the sensors of ``operator`` (:class:`SensorOperator`) re-balanced.
    Returns (contact forces λ (a,), their rows A (a, m), the new q)."""
    from scipy.optimize import nnls

    near = np.flatnonzero(ok & (gap < margin + BAND))
    a_rows = -np.einsum("kc,kcm->km", normal[near], phi_nodes[near])
    rhs = gap[near] - margin + a_rows @ q
    # q(λ) = q₀ + Bλ with the sensors re-balanced, and the QP's matrix M = -AB (:func:`_contact_response`)
    m_mat, b_mat = _contact_response(a_rows, operator)
    r = rhs - a_rows @ q0
    chol = _cholesky(0.5 * (m_mat + m_mat.T))
    lam_a = nnls(chol.T, -np.linalg.lstsq(chol, r, rcond=None)[0], maxiter=50 * len(r))[0]
    on = lam_a > 0
    if on.any():  # polish: the active constraints exactly tight (NNLS stops at its own tolerance)
        polished = np.linalg.lstsq(m_mat[np.ix_(on, on)], -r[on], rcond=None)[0]
        if np.all(polished >= 0):
            lam_a[on] = polished
    return lam_a, a_rows, q0 + b_mat @ lam_a


def _contact_pass_fast(operator, phi_nodes, q, q0, gap, normal, ok, margin):
    """:func:`_contact_pass` with the small solves by LAPACK directly (the NNLS's right-hand side a
    triangular solve; the polish a Cholesky solve where the block is positive definite, else least
    squares as the reference): the same QP, the same result to rounding."""
    from scipy.linalg.lapack import dpotrf, dpotrs, dtrtrs
    from scipy.optimize import nnls

    near = np.flatnonzero(ok & (gap < margin + BAND))
    a_rows = -np.einsum("kc,kcm->km", normal[near], phi_nodes[near])
    m_mat, b_mat = _contact_response(a_rows, operator)
    r = gap[near] - margin + a_rows @ (q - q0)
    chol, lower = _factor(0.5 * (m_mat + m_mat.T))
    if lower:
        rhs, info = dtrtrs(chol, r, lower=1)
    if not lower or info != 0:
        rhs = np.linalg.lstsq(chol, r, rcond=None)[0]
    lam_a = nnls(chol.T, -rhs, maxiter=50 * len(r))[0]
    on = np.flatnonzero(lam_a > 0)
    if len(on):  # polish, as _contact_pass
        block = m_mat[on][:, on]
        factor, info = dpotrf(block, lower=1, clean=0)
        if info == 0:
            polished, info = dpotrs(factor, -r[on], lower=1)
        if info != 0:
            polished = np.linalg.lstsq(block, -r[on], rcond=None)[0]
        if np.all(polished >= 0):
            lam_a[on] = polished
    return lam_a, a_rows, q0 + b_mat @ lam_a


def _factor(matrix: np.ndarray) -> tuple[np.ndarray, bool]:
    """:func:`_cholesky`'s factor and whether it is the (lower triangular) Cholesky factor."""
    from scipy.linalg.lapack import dpotrf

    scale = max(np.trace(matrix) / len(matrix), 1e-300)
    for jitter in (1e-12, 1e-10, 1e-8, 1e-6):
        shifted = matrix.copy()
        shifted.flat[::len(matrix) + 1] += jitter * scale
        factor, info = dpotrf(shifted, lower=1, clean=1)
        if info == 0:
            return factor, True
    return _cholesky(matrix), False


class SensorOperator(NamedTuple):
    """How contact forces move the shape with the sensors re-balanced, for one pattern of acting sensors
    and springs: a force f (m,) in modal space moves it by K f, K = Λ⁻¹(PᵀG⁻¹PΛ⁻¹ - I), G = PΛ⁻¹Pᵀ + C
    over the acting sensors; kept as its factors, -K = Λ^-½(I - XᵀG⁻¹X)Λ^-½ with X = PΛ^-½
    (:func:`_contact_response`)."""

    x_mat: np.ndarray  # (3S, m) X = PΛ^-½, every sensor's rows
    g_inv: np.ndarray  # (3S, 3S) G⁻¹ of the acting sensors (:func:`_sensor_inverse`), zero at the others
    spring_root: np.ndarray  # (3S,) √C of the acting sensors' springs (m/N), zero at the others
    eigenvalues: np.ndarray  # (m,) Λ
    g_mat: np.ndarray  # (3S, 3S) G = XXᵀ + C of the acting sensors, zero at the others


def sensor_operator(lam, P, gram, comp, acting) -> SensorOperator:
    """:class:`SensorOperator` of the ``acting`` (3S,) sensor rows of ``P`` (3S, m), springs ``comp`` (3S,) m/N;
    gram : PΛ⁻¹Pᵀ (3S, 3S)."""
    act = np.flatnonzero(acting)
    g_inv = np.zeros((len(P), len(P)))
    g_inv[np.ix_(act, act)] = _sensor_inverse(gram, comp, acting)
    spring = np.zeros(len(P))
    spring[act] = np.where(np.isfinite(comp[act]), comp[act], 0.0)  # as _sensor_inverse's
    g_mat = np.zeros((len(P), len(P)))
    g_mat[np.ix_(act, act)] = gram[np.ix_(act, act)] + np.diag(spring[act])
    return SensorOperator(P / np.sqrt(lam), g_inv, np.sqrt(spring), lam, g_mat)


def _response_rows(a_root: np.ndarray, operator: SensorOperator):
    """Of contact rows Ã = AΛ^-½ (a, m): (Ã⊥ = Ã(I - XᵀG⁻¹X) (a, m), YG⁻¹ (a, 3S), YG⁻¹√C (a, 3S)), Y = ÃXᵀ."""
    y = a_root @ operator.x_mat.T
    y_g = y @ operator.g_inv
    # once refined (YG⁻¹ G = Y to rounding): G is ill-conditioned (sensors the modes barely tell apart),
    # and what YG⁻¹ misses there would move the sensors (some 10⁻⁹ of a push)
    y_g += (y - y_g @ operator.g_mat) @ operator.g_inv
    return a_root - y_g @ operator.x_mat, y_g, y_g * operator.spring_root


def _contact_response(a_rows: np.ndarray, operator: SensorOperator) -> tuple[np.ndarray, np.ndarray]:
    """(M = -AKAᵀ (a, a), B = KAᵀ (m, a)) of contact rows A (a, m): the shape moves by Bλ under contact
    forces λ, the rows' clearances by -Mλ.

    As M = Ã⊥Ã⊥ᵀ + YG⁻¹CG⁻¹Yᵀ (:func:`_response_rows`; I - XᵀG⁻¹X = (I - XᵀG⁻¹X)² + XᵀG⁻¹CG⁻¹X, as
    G = XXᵀ + C): two positive parts.  -AKAᵀ formed directly loses digits where the sensors nearly hold
    a node (M some 10⁻⁶ of AΛ⁻¹Aᵀ): its forces were 3e-10 from the exact ones on the demo, these 1e-15
    (tests/sim/test_contact_fast.py)."""
    inv_root = 1.0 / np.sqrt(operator.eigenvalues)
    perp, _, sprung = _response_rows(a_rows * inv_root, operator)
    return perp @ perp.T + sprung @ sprung.T, -(perp * inv_root).T


def _active_sets(lam, solves, phi_nodes, phi_flat, query, offsets, q0, allowed, margin, gap0, normal0,
                 guess: bool = True, shift: np.ndarray | None = None):
    """:func:`_active_set` of several frames at once, with what the caller already has.

    solves : per frame, the :class:`SensorOperator` of its acting sensors (shared by the frames with
    the same acting sensors and springs); q0 : (n, m); allowed : (n, k); offsets : (n, 3); gap0 (n, k)
    and normal0 (n, k, 3): the clearances at q0 (from the compiled pass over every frame);
    query : a :class:`~tonguevis.sim.contact_kernel.Clearance` of the candidates.  The frames
    take their passes in step, so each later pass queries the clearances of all the frames
    still going in one compiled call; each frame's passes, QP and guard are :func:`_active_set`'s:
    the same result to rounding (tests/sim/test_contact_fast.py).  Each pass's QP: from a guessed
    active set for every frame at once (:func:`_guessed_passes`), by NNLS
    (:func:`_contact_pass_fast`) where no guess holds; guess=False: by NNLS everywhere.
    shift : (n, k, 3) m or None, added to every candidate's displacement Φq (the part of the drawn shape that
    is not linear in q, held fixed: :func:`correct_frames`).
    Returns (q (n, m), the modal contact force -Aᵀλ (n, m), the number of contact forces (n,)):
    q0, 0 and 0 where the frame keeps its contact-free shape.
    """
    n, m = q0.shape
    q = np.array(q0, copy=True)
    if n == 0:
        return q, np.zeros((0, m)), np.zeros(0, dtype=np.int64)
    forces = np.zeros(allowed.shape)  # (n, k) each frame's λ over the candidates, after its last pass
    external = np.zeros((n, m))  # -Aᵀλ of each frame's last pass
    going = np.arange(n)
    for n_pass in range(MAX_PASSES):
        if len(going) == 0:
            break
        if n_pass:
            u = (q[going] @ phi_flat.T).reshape(len(going), -1, 3)
            gap, normal = query(u if shift is None else u + shift[going], offsets[going], normals=True)
        else:
            gap, normal = gap0[going], normal0[going]
        # a frame goes on while a candidate it may constrain is inside the margin (NaN: off the palate)
        inside = np.any(allowed[going] & (gap < margin - 1e-7), axis=1)
        js = np.flatnonzero(inside)
        ok = allowed[going[js]] & np.isfinite(gap[js])
        if guess:  # the frames whose QP a guessed active set solves exactly (see _guessed_passes)
            done = _guessed_passes(solves, going[js], phi_nodes, q, q0, gap[js], normal[js], ok, margin, forces,
                                   external, first=n_pass == 0, points=query.base)
        else:
            done = np.zeros(len(js), dtype=bool)
        for j in np.flatnonzero(~done):  # the others: the QP by NNLS, as the reference
            i = going[js[j]]
            lam_a, rows, q[i] = _contact_pass_fast(solves[i], phi_nodes, q[i], q0[i], gap[js[j]],
                                                   normal[js[j]], ok[j], margin)
            near = np.flatnonzero(ok[j] & (gap[js[j]] < margin + BAND))
            used = lam_a > 0
            forces[i] = 0.0
            forces[i, near[used]] = lam_a[used]
            external[i] = -(rows[used].T @ lam_a[used])
        going = going[inside]
    # the guard, every frame at once: a push much further than the surface was inside has failed
    depth = np.maximum(0.0, -np.fmin.reduce(np.where(allowed, gap0, np.nan), axis=1, initial=np.inf))
    moved = np.abs((q - q0) @ phi_flat.T).reshape(n, -1, 3)
    moved = np.where(allowed[:, :, None], moved, 0.0).reshape(n, -1).max(axis=1, initial=0.0)
    count = np.count_nonzero(forces > 0, axis=1)
    kept = (count > 0) & np.isfinite(moved) & (moved <= 2 * depth + 2e-3)
    return np.where(kept[:, None], q, q0), np.where(kept[:, None], external, 0.0), np.where(kept, count, 0)


#: A guessed active set is taken only with this much to spare: each of its contact forces above
#: GUESS_MARGIN times the largest, each other near candidate's linearised clearance above the margin
#: by GUESS_MARGIN times the largest |residual|, and its block's condition number below GUESS_CONDITION
#: (so neither the 1e-12 jitter of the reference's factor nor rounding can move it: λ equal to 1e-10).
GUESS_MARGIN = 1e-5
GUESS_CONDITION = 1e4
GUESS_ROUNDS = 10  # guesses a frame tries (each corrected from the last) before the NNLS takes it
GUESS_MAX = 24  # largest active set guessed; more goes to the NNLS
GUESS_SPREAD = 8e-3  # m: candidates this far apart at rest press on the palate in different places


def _guessed_passes(solves, frames, phi_nodes, q, q0, gap, normal, ok, margin, forces, external, first=False,
                    points=None):
    """One pass of :func:`_active_sets` for the frames whose QP a guessed active set solves; the rest untouched.

    solves : per frame (row of q), its :class:`SensorOperator`;
    frames : (F,) the frames (rows of q, q0 (n, m), forces (n, k), external (n, m)) taking a pass;
    gap (F, k) m, normal (F, k, 3), ok (F, k) their clearances at q and the candidates that may
    get a constraint; forces: each frame's λ over the candidates after its last pass (its active set
    the positive ones); first: the frames' first pass (q = q0); points (k, 3): the candidates' rest
    positions, m (with them a guess grows in several places at once, see below).  The QP of a pass (:func:`_contact_pass_fast`'s, min ½λᵀMλ + rᵀλ over λ >= 0, a
    strictly convex problem with one solution) is solved by NNLS there; here a guess S of its active
    set (the frame's after its last pass, else its deepest candidate) is solved as equalities,
    M_SS λ_S = -r_S, every frame at once, and taken when it satisfies the optimality conditions with
    room to spare (λ_S > 0 and w = Mλ + r > 0 off S, by GUESS_MARGIN; M_SS well conditioned): then it
    is that one solution, the set NNLS finds and the λ its polish computes (M_SS λ_S = -r_S again),
    so the same result to rounding; a wrong set never passes (tests/sim/test_contact_fast.py).
    A guess that fails is corrected (the forces that came out negative leave, the candidate furthest
    inside joins, and so do the furthest inside of up to two other places GUESS_SPREAD from every
    member: the tip and the sides press at once; a singular block starts again from the deepest) up to
    GUESS_ROUNDS times.  The frames taken
    have q, forces and external (-Aᵀλ) filled; returns (F,) bool, which.  Vectorised over the frames:
    one pass's Python costs a few microseconds a frame instead of some 90 (most frames'
    first guess holds: consecutive frames press on the same few nodes).

    K applied by its factors (-K = Λ^-½(I - XᵀG⁻¹X)Λ^-½, :class:`SensorOperator`): with the guessed
    rows Ã = AΛ^-½, Y = ÃXᵀ and Ã⊥ = Ã - YG⁻¹X, M_SS = Ã⊥Ã⊥ᵀ + YG⁻¹CG⁻¹Yᵀ and the move
    Bλ = KAᵀλ = -Λ^-½Ã⊥ᵀλ, so a row costs m + 3S numbers once a call, no (m, m) product per row
    and none per sensor pattern; and M_SS is a sum of two positive parts, where -AKAᵀ loses
    digits (a node the sensors nearly hold: M some 10⁻⁶ of AΛ⁻¹Aᵀ): within 10⁻¹⁵ of M in 40 digits.
    """
    n_f, k = gap.shape
    m = q.shape[1]
    done = np.zeros(n_f, dtype=bool)
    if n_f == 0:
        return done
    near = ok & (gap < margin + BAND)
    # only the candidates near the palate in some frame matter (a few dozen of some 300)
    cols = np.flatnonzero(near.any(axis=0))
    k = len(cols)
    near, gap, normal = near[:, cols], gap[:, cols], normal[:, cols]
    phi_nodes = phi_nodes[cols]
    phi_flat = phi_nodes.reshape(3 * k, m)
    normal_flat = normal.reshape(n_f, 3 * k)
    # each frame's sensor pattern (frames with the same acting sensors and springs share an operator)
    pattern_of: dict = {}
    pattern = np.array([pattern_of.setdefault(id(solves[i]), len(pattern_of)) for i in frames], dtype=np.int64)
    operators = [None] * len(pattern_of)
    for j, i in enumerate(frames):
        if operators[pattern[j]] is None:
            operators[pattern[j]] = solves[i]
    x_mat = operators[0].x_mat  # PΛ^-½: the same for every pattern
    inv_root = 1.0 / np.sqrt(operators[0].eigenvalues)  # Λ^-½
    n_y = len(x_mat)
    # each (frame, candidate)'s Ã⊥, YG⁻¹ and YG⁻¹√C, formed once a call (a guess keeps most of its last)
    slot = np.full((n_f, k), -1, dtype=np.int64)
    store = np.empty((8 * n_f, m + 2 * n_y))
    buffer = store[:0]
    # r = gap - margin + A(q - q0) at every candidate, A's row i being -n_iᵀΦ_i
    r_all = gap - margin
    if not first:
        shift = ((q[frames] - q0[frames]) @ phi_flat.T).reshape(n_f, k, 3)
        r_all = r_all - np.einsum("fkc,fkc->fk", normal, shift)
    # the first guess: the frame's active set after its last pass, else its deepest candidate
    guess = near & (forces[frames][:, cols] > 0)
    deepest = np.zeros_like(guess)
    deepest[np.arange(n_f), np.argmin(np.where(near, r_all, np.inf), axis=1)] = True
    fresh = ~guess.any(axis=1)
    guess[fresh] = deepest[fresh]
    apart = None
    if points is not None:  # pairs of candidates in different places: never near-duplicate rows
        at = points[cols]
        apart = np.linalg.norm(at[:, None] - at[None], axis=2) >= GUESS_SPREAD
        guess[fresh] = _spread(guess[fresh], near[fresh] & (r_all[fresh] < 0), r_all[fresh], apart)
    pending = np.arange(n_f)
    for _ in range(GUESS_ROUNDS):
        counts = guess[pending].sum(axis=1)
        pending = pending[(counts > 0) & (counts <= GUESS_MAX)]
        if len(pending) == 0:
            break
        g = guess[pending]
        n_p = len(pending)
        # the guessed (frame, candidate) pairs, frame by frame, candidates ascending (as NNLS's rows)
        rows, cand = np.nonzero(g)
        counts = np.bincount(rows, minlength=n_p)
        first_pair = np.cumsum(counts) - counts
        at_frame = pending[rows]
        fresh_pairs = np.flatnonzero(slot[at_frame, cand] < 0)  # rows not formed in an earlier round
        if len(fresh_pairs):
            f_new, c_new = at_frame[fresh_pairs], cand[fresh_pairs]
            formed = -np.einsum("nc,ncm->nm", normal[f_new, c_new], phi_nodes[c_new]) * inv_root  # Ã, as _contact_response's
            new_rows = np.empty((len(formed), m + 2 * n_y))
            for p, op in enumerate(operators):  # each pair with its frame's sensors
                of = np.flatnonzero(pattern[f_new] == p) if len(operators) > 1 else slice(None)
                for part, part_of in zip(np.split(new_rows, [m, m + n_y], axis=1), _response_rows(formed[of], op)):
                    part[of] = part_of
            used = len(buffer)
            if used + len(fresh_pairs) > len(store):
                grown = np.empty((2 * (used + len(fresh_pairs)), store.shape[1]))
                grown[:used] = buffer
                store = grown
            store[used:used + len(fresh_pairs)] = new_rows
            slot[f_new, c_new] = np.arange(used, used + len(fresh_pairs))
            buffer = store[:used + len(fresh_pairs)]
        held = slot[at_frame, cand]  # each pair's row in the store
        r_pairs = r_all[at_frame, cand]
        lam_pairs = np.empty(len(rows))
        u = np.empty((n_p, m))  # Ã⊥ᵀλ
        z = np.empty((n_p, n_y))  # G⁻¹Yᵀλ
        well, solvable = np.empty(n_p, dtype=bool), np.empty(n_p, dtype=bool)
        for size in np.unique(counts):  # the frames with as many guessed as one block each: no padding
            of = np.flatnonzero(counts == size)
            pairs = first_pair[of][:, None] + np.arange(size)
            block = buffer[held[pairs]]  # (n, s, m + 2·3S)
            perp, y_g, sprung = block[:, :, :m], block[:, :, m:m + n_y], block[:, :, m + n_y:]
            # M_SS = Ã(I - XᵀG⁻¹X)Ãᵀ = Ã⊥Ã⊥ᵀ + YG⁻¹CG⁻¹Yᵀ: two positive parts, no cancellation
            m_ss = np.matmul(perp, perp.transpose(0, 2, 1)) + np.matmul(sprung, sprung.transpose(0, 2, 1))
            m_ss = 0.5 * (m_ss + m_ss.transpose(0, 2, 1))
            eig = np.linalg.eigvalsh(m_ss)
            top_eig = np.maximum(eig[:, -1], 1e-300)
            well[of] = eig[:, 0] * GUESS_CONDITION > top_eig  # to be taken
            solvable[of] = eig[:, 0] > 1e-10 * top_eig  # to guide the next guess
            with np.errstate(all="ignore"):
                lam_of = np.linalg.solve(np.where(solvable[of, None, None], m_ss, np.eye(size)[None]),
                                         -r_pairs[pairs][:, :, None])[:, :, 0]
            lam_pairs[pairs] = lam_of
            u[of] = np.matmul(lam_of[:, None, :], perp)[:, 0]
            z[of] = np.matmul(lam_of[:, None, :], y_g)[:, 0]
        dq = -u * inv_root  # Bλ = KAᵀλ = -Λ^-½Ã⊥ᵀλ (P, m)
        moved = (dq @ phi_flat.T) * normal_flat[pending]  # the candidates' moves along their normals
        w = r_all[pending] + (moved[:, 0::3] + moved[:, 1::3] + moved[:, 2::3])
        off = near[pending] & ~g
        top = np.maximum.reduceat(lam_pairs, first_pair)
        scale = np.max(np.where(near[pending], np.abs(r_all[pending]), 0.0), axis=1)
        positive = (np.bincount(rows, lam_pairs <= GUESS_MARGIN * top[rows], minlength=n_p) == 0) & (top > 0)
        feasible = np.all(~off | (w > GUESS_MARGIN * scale[:, None]), axis=1)
        finite = np.bincount(rows, ~np.isfinite(lam_pairs), minlength=n_p) == 0
        taken = well & positive & feasible & finite
        got = frames[pending[taken]]
        q[got] = q0[got] + dq[taken]
        forces[got] = 0.0
        pairs = np.flatnonzero(taken[rows])
        forces[frames[at_frame[pairs]], cols[cand[pairs]]] = lam_pairs[pairs]
        external[got] = -(u[taken] / inv_root + z[taken] @ x_mat / inv_root)  # -Aᵀλ = -Λ^½(Ã⊥ᵀλ + XᵀG⁻¹Yᵀλ)
        done[pending[taken]] = True
        # the next guess: the forces that came out negative leave, the candidate furthest inside joins
        lam_full = np.zeros((n_p, k))
        lam_full[rows, cand] = lam_pairs
        fixed = g & (lam_full > 0)
        w_off = np.where(off, w, np.inf)
        worst = np.argmin(w_off, axis=1)
        join = np.flatnonzero(w_off[np.arange(n_p), worst] < 0)
        fixed[join, worst[join]] = True
        if apart is not None and len(join):
            fixed[join] = _spread(fixed[join], off[join] & (w[join] < 0), w[join], apart)
        # a singular block (rows of near-duplicate nodes): start again from the deepest node, once
        restart = ~solvable & np.any(g != deepest[pending], axis=1)
        fixed[restart] = deepest[pending[restart]]
        moved = np.any(fixed != g, axis=1) & ~taken
        guess[pending] = fixed
        pending = pending[moved]
    return done


def _spread(guess: np.ndarray, inside: np.ndarray, score: np.ndarray, apart: np.ndarray, places: int = 2) -> np.ndarray:
    """``guess`` (P, k) bool with, up to ``places`` times, the lowest-``score`` candidate of ``inside`` (P, k)
    that is ``apart`` (k, k) bool from every member added to it."""
    close = ~apart
    # the candidates close to a member (float32: exact for these counts, and half a float64 product's time)
    blocked = (guess.astype(np.float32) @ close.astype(np.float32)) > 0
    for _ in range(places):
        pick = np.where(inside & ~guess & ~blocked, score, np.inf)
        best = np.argmin(pick, axis=1)
        rows = np.flatnonzero(np.isfinite(pick[np.arange(len(pick)), best]))
        if len(rows) == 0:
            break
        guess[rows, best[rows]] = True
        blocked[rows] |= close[best[rows]]
    return guess


def _sensor_inverse(gram, comp, acting):
    """G⁻¹ of the acting sensors (pseudo-inverse, as :func:`_active_set`): (a, a), a = acting.sum()."""
    act = np.flatnonzero(acting)
    g_c = gram[np.ix_(act, act)] + np.diag(np.where(np.isfinite(comp[act]), comp[act], 0.0))
    return np.linalg.pinv(g_c)


def _solve_frames_fast(lam, P, gram, phi_nodes, cand_pts, palate, jaw_offset, c_all, comp3, acting, q_all, targets,
                       sensor_pts, near_sensor, margin, out_targets, external, active_count, conflicts):
    """:func:`solve_contact`'s frames on the compiled clearances; fills the last four arguments in place.

    Every frame's clearances at once (one compiled pass); the active-set solve only where a
    candidate the solve may constrain is inside the margin (the reference's first pass stops
    at once everywhere else: nothing to do); the same conflicts, in the same order."""
    from tonguevis.sim.contact_kernel import Clearance, clearances

    n_frames, k, m = len(q_all), len(cand_pts), len(lam)
    phi_flat = np.ascontiguousarray(phi_nodes.reshape(3 * k, m))
    query = Clearance(palate, cand_pts)
    u = (q_all @ phi_flat.T).reshape(n_frames, k, 3)
    gap, _ = query(u, jaw_offset)
    sensor_gap, _ = clearances(palate, sensor_pts, np.nan_to_num(targets), jaw_offset)
    above_all = (sensor_gap < -CONFLICT_TOLERANCE) & np.all(np.isfinite(targets), axis=2)  # (F, S)
    low = np.flatnonzero(np.fmin.reduce(gap, axis=1, initial=np.inf) < margin)  # fmin: NaN (off the palate) ignored
    allowed = ~((above_all[low].astype(np.int64) @ near_sensor.T.astype(np.int64)) > 0)  # (len(low), k)
    at, sensor = np.nonzero(above_all[low])  # frame by frame, each frame's sensors in order: the reference's order
    conflicts.extend(zip(low[at].tolist(), sensor.tolist()))
    inside = np.any(allowed & np.isfinite(gap[low]) & (gap[low] < margin - 1e-7), axis=1)
    frames, allowed = low[inside], allowed[inside]
    _, normals = query(u[frames], jaw_offset[frames], normals=True)
    operators: dict = {}
    solves = []
    for f in frames:
        key = (acting[f].tobytes(), comp3[f][acting[f]].tobytes())
        if key not in operators:
            operators[key] = sensor_operator(lam, P, gram, comp3[f], acting[f])
        solves.append(operators[key])
    q, pushed, count = _active_sets(lam, solves, phi_nodes, phi_flat, query, jaw_offset[frames], q_all[frames],
                                    allowed, margin, gap[frames], normals)
    kept = count > 0
    frames = frames[kept]
    external[frames] = pushed[kept]
    active_count[frames] = count[kept]
    out_targets[frames] = (q[kept] @ P.T).reshape(len(frames), *out_targets.shape[1:])


def _cholesky(matrix: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of a symmetric PSD matrix, with the smallest jitter that makes it succeed.

    Near-duplicate clearance rows (neighbouring nodes against the same patch of
    palate) make M singular to round-off.
    """
    scale = max(np.trace(matrix) / len(matrix), 1e-300)
    for jitter in (1e-12, 1e-10, 1e-8, 1e-6):
        try:
            return np.linalg.cholesky(matrix + jitter * scale * np.eye(len(matrix)))
        except np.linalg.LinAlgError:
            continue
    w, v = np.linalg.eigh(matrix)
    return v * np.sqrt(np.maximum(w, 1e-6 * scale))  # a square root; not triangular, fine for the solves


def correct_frames(eigenvalues, phi_nodes, phi_s, q, points, candidates, palate, jaw_offset, allowed=None,
                   margin: float = MARGIN, compliance: float = 0.0,
                   backend: str = "warp", shift: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Dynamic shapes (F, m) moved out of the palate where they went in: (corrected q, frames corrected).

    The integrator does not see the palate (only the contact forces of the
    static solution): inertia can still carry the free parts of the tongue
    into it.  Each such frame is projected onto the nearest shape, in the
    elastic-energy metric, that keeps every sensor node where it is and every
    candidate node below the palate: the same QP as :func:`solve_contact`
    with the sensors at their dynamic positions, held by springs of ``compliance``
    (m/N; 0 = exactly, the paper's constraint).  allowed : (F, k) bool,
    candidates that may get a constraint (False near a conflicting sensor).
    backend : "warp" (default): every frame's clearances in one compiled pass and the frames
    that went in solved together (:func:`_active_sets`); "numpy": the
    reference (the same q to rounding).
    shift : (F, k, 3) m or None: added to each candidate's displacement Φq, held fixed (modal warping's
    rotation of the shape, R̃Φq - Φq at a nearby q: the candidates are then kept out as drawn).
    """
    lam = np.asarray(eigenvalues, dtype=np.float64)
    n_s = phi_s.shape[0]
    P = phi_s.reshape(3 * n_s, len(lam))
    gram = (P / lam) @ P.T
    cand_pts = points[candidates]
    if check_backend(backend) == "warp":
        from tonguevis._blas import single_threaded_blas

        with single_threaded_blas():  # as solve_contact's
            return _correct_frames_fast(lam, P, gram, phi_nodes, q, cand_pts, palate, jaw_offset, allowed, margin,
                                        compliance, shift)
    u = np.einsum("kcm,fm->fkc", phi_nodes, q) + (0.0 if shift is None else shift)
    gap, _ = clearance_at(palate, cand_pts[None] + u, jaw_offset)
    if allowed is not None:
        gap = np.where(allowed, gap, np.nan)
    out = np.array(q, copy=True)
    frames = np.flatnonzero(np.nanmin(np.where(np.isfinite(gap), gap, np.inf), axis=1) < margin - 1e-7)
    ones = np.ones(3 * n_s, dtype=bool)
    for f in frames:
        ok = np.ones(len(candidates), bool) if allowed is None else allowed[f]
        at = cand_pts if shift is None else cand_pts + shift[f]  # a fixed shift is a moved rest, frame by frame
        out[f] = _active_set(lam, P, gram, phi_nodes, at, palate, jaw_offset[f], P @ q[f], np.full(3 * n_s, compliance),
                             ones, q[f], ok, margin)[0]
    return out, frames


def _correct_frames_fast(lam, P, gram, phi_nodes, q, cand_pts, palate, jaw_offset, allowed, margin, compliance,
                         shift=None):
    """:func:`correct_frames` on the compiled clearances (see there)."""
    from tonguevis.sim.contact_kernel import Clearance

    n_frames, k, m = len(q), len(cand_pts), len(lam)
    phi_flat = np.ascontiguousarray(phi_nodes.reshape(3 * k, m))
    query = Clearance(palate, cand_pts)
    u = (q @ phi_flat.T).reshape(n_frames, k, 3)
    if shift is not None:
        u = u + shift
    gap, _ = query(u, jaw_offset)
    if allowed is not None:
        gap = np.where(allowed, gap, np.nan)
    out = np.array(q, copy=True)
    frames = np.flatnonzero(np.fmin.reduce(gap, axis=1, initial=np.inf) < margin - 1e-7)
    if len(frames) == 0:
        return out, frames
    operator = sensor_operator(lam, P, gram, np.full(len(P), compliance), np.ones(len(P), dtype=bool))
    _, normals = query(u[frames], jaw_offset[frames], normals=True)
    ok = np.ones((len(frames), k), bool) if allowed is None else allowed[frames]
    out[frames] = _active_sets(lam, [operator] * len(frames), phi_nodes, phi_flat, query,
                               jaw_offset[frames], q[frames], ok, margin, gap[frames], normals,
                               shift=None if shift is None else shift[frames])[0]
    return out, frames


def penetration(displacements: np.ndarray, points: np.ndarray, nodes: np.ndarray, palate, jaw_offset: np.ndarray,
                exclude: np.ndarray | None = None) -> np.ndarray:
    """(F,) deepest penetration (m, >= 0) of the given nodes into the palate, per frame.

    displacements : (F, n, 3); exclude : (F, len(nodes)) bool, nodes not to count (sensor conflicts).
    """
    gap, _ = clearance_at(palate, points[nodes][None] + displacements[:, nodes], jaw_offset)
    if exclude is not None:
        gap = np.where(exclude, np.nan, gap)
    deepest = np.nanmin(np.where(np.isfinite(gap), gap, np.inf), axis=1)
    return np.maximum(0.0, -np.where(np.isfinite(deepest), deepest, 0.0))


#: m: surface triangles whose three nodes are this close to the palate are in contact.
TOUCH = 3e-4


def node_areas(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(n,) m²: the surface area each node stands for, a third of each surface triangle ``faces`` (f, 3)
    it belongs to (at ``points`` (n, 3) m); 0 off the surface."""
    a, b, c = points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]]
    third = np.linalg.norm(np.cross(b - a, c - a), axis=1) / 6.0
    out = np.zeros(len(points))
    np.add.at(out, faces.ravel(), np.repeat(third, 3))
    return out


def contact_frames(displacements: np.ndarray, points: np.ndarray, candidates: np.ndarray, palate,
                   jaw_offset: np.ndarray, faces: np.ndarray, exclude: np.ndarray | None = None,
                   touch: float = TOUCH, backend: str = "numpy",
                   areas: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per frame of ``displacements`` (F, n, 3) m: (deepest penetration (F,) m, contact area (F,) m²).

    Penetration as :func:`penetration` over the ``candidates`` (exclude : (F, k)
    candidates not counted: sensor conflicts); contact area: the surface the candidates
    within ``touch`` of the palate (or inside it) stand for, each node's share of the surface
    triangles ``faces`` (f, 3) at rest (:func:`node_areas`; ``areas`` (n,) m² when the caller has
    them).  So a frame with any penetration or touch has an area, however large the mesh's
    triangles: a measure needing a triangle's three nodes within ``touch`` read 0 mm² on a
    tongue placed at 1.6 times the model's size while its dorsum pressed into the palate.
    ``jaw_offset`` (F, 3) carries the tongue into the palate's frame.  One clearance
    evaluation serves both, and any run of frames gives the same values as the whole motion,
    so a long motion is measured chunk by chunk (:func:`tonguevis.sim.figures.frame_figures`).
    backend : "numpy" (default) or "warp" (the clearances in one compiled pass, the same to 1e-12 m).
    """
    if check_backend(backend) == "warp":
        from tonguevis.sim.contact_kernel import clearances

        every = len(candidates) == displacements.shape[1] and np.array_equal(candidates, np.arange(len(candidates)))
        gap, _ = clearances(palate, points[candidates], displacements if every else displacements[:, candidates],
                            jaw_offset)  # (the figures pass the candidates' displacements alone: no copy)
    else:
        gap, _ = clearance_at(palate, points[candidates][None] + displacements[:, candidates], jaw_offset)
    counted = gap if exclude is None else np.where(exclude, np.nan, gap)
    deepest = np.fmin.reduce(counted, axis=1, initial=np.inf)  # NaN (off the palate, excluded) ignored
    pen = np.maximum(0.0, -np.where(np.isfinite(deepest), deepest, 0.0))
    if areas is None:
        areas = node_areas(points, faces)
    close = gap < touch  # (F, k); NaN: False
    area = close.astype(np.float64) @ np.asarray(areas, dtype=np.float64)[candidates]
    return pen, area
