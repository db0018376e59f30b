"""The one constrained solve: modal forces balanced against (compliant) warped sensor constraints.

Every solver of tonguevis (the Newmark integrator, its compiled kernel, the
quasi-static baseline) solves, per frame, for an unknown x with q = q* + β x:

    A x = b + Φ_sᵀ R̃_sᵀ μ,          R̃(W_s q) Φ_s q + C μ = c,

A diagonal, μ the nodal sensor forces (N), c the sensor targets (m) and C the
sensor compliance (m/N; C = 0 holds a sensor exactly, as the paper's
Lagrange multipliers do; C = 1/k is a spring of stiffness k between sensor and
node, still in the multiplier form).  The dynamic solve has x = q̈, A = I + h/2
C_q + β Λ, β = h²/4; the quasi-static one has x = q, A = Λ, b = 0, q* = 0, β = 1.

The sensor force enters modal space as modal warping brings every external
force (Choi & Ko 2005: f_q = Φᵀ R̃ᵀ f).  Using the full constraint gradient
instead (a textbook Lagrange multiplier) adds ∂R̃/∂w terms that, in trials on
the ArtiSynth tongue, fed a growing oscillation across syllables.

Newton's method from ``x_start`` (the previous frame): the first iterate solves
the problem linearised there (exact when nothing is warped); then full Newton
steps (∂R̃/∂w on both equations) with the sensor-rotation change capped at
``MAX_ROTATION_STEP`` and a backtracking line search on the residual norm that
never accepts a step raising it.  Every product with the m modes folds into
the constant 3S × 3S matrices Q = Φ_s A⁻¹ Φ_sᵀ and P = W_s A⁻¹ Φ_sᵀ: with
y = β X W_s Δx + R̃ᵀΔμ the Newton system

    (A - β Φ_sᵀ X W_s) Δx - Φ_sᵀ R̃ᵀ Δμ = -r_stat,   β (R̃ Φ_s + D W_s) Δx + C Δμ = r_con

becomes Δx = A⁻¹(Φ_sᵀ y - r_stat) and two 3S × 3S solves, where D = ∂g/∂w and
X = ∂(R̃ᵀμ)/∂w (both block diagonal).  :mod:`tonguevis.sim.newmark_kernel` runs
the same algorithm compiled; a test proves both equal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tonguevis.sim.rotation import rotate_accumulated_jacobian

MAX_ROTATION_STEP = 0.5  # rad: largest change of a sensor node's rotation vector per Newton step
STATIONARITY_RTOL = 1e-10  # force balance, relative to the size of its terms
#: A frame whose sensor nodes rotate further than this (rad) has run away onto a
#: large-rotation branch no tongue takes; it is recovered (see :func:`solve_frame`'s callers).
RUNAWAY_ROTATION = 1.5


@dataclass
class ConstraintSettings:
    """Newton settings shared by every solver.

    tolerance : constraint residual (m, max over sensor coordinates) to stop.
    max_iterations : Newton iterations per frame.
    warping : whether the constraint holds the warped (True) or linear positions.
    """

    tolerance: float = 1e-8
    max_iterations: int = 20
    warping: bool = True


def sensor_constraint(q: np.ndarray, phi_s: np.ndarray, w_s: np.ndarray, warping: bool):
    """Warped sensor displacements f(q) (S, 3) and the Jacobian ∂f/∂q (3S, m).

    phi_s, w_s : (S, 3, m) sensor rows of Φ and W.
    """
    d = phi_s @ q  # (S, 3)
    if not warping:
        return d, phi_s.reshape(-1, phi_s.shape[-1])
    w = w_s @ q
    g, rot, dg_dw = rotate_accumulated_jacobian(w, d)
    jac = rot @ phi_s + dg_dw @ w_s  # (S, 3, m)
    return g, jac.reshape(-1, jac.shape[-1])


def point_stiffness(eigenvalues: np.ndarray, phi_s: np.ndarray) -> float:
    """The model's own static stiffness at its sensor nodes, N/m: 1 / mean diag(Φ_s Λ⁻¹ Φ_sᵀ).

    The force a sensor node needs per metre of displacement when nothing else
    holds the tongue (the modes' anchors aside): the natural unit of a sensor
    spring's stiffness, so a dimensionless multiple of it means the same on
    any mesh, material or number of modes.  phi_s : (S, 3, m).
    """
    lam = np.asarray(eigenvalues, dtype=np.float64)
    phi2 = np.asarray(phi_s, dtype=np.float64).reshape(-1, len(lam))
    return float(1.0 / np.mean(np.sum(phi2 * phi2 / lam, axis=1)))


#: Frames solved in one batch: the (frames, 3S, 3S) systems of a 30-minute recording at once took 0.7 GB.
FRAMES_PER_SOLVE = 8192


def compliant_shapes(eigenvalues: np.ndarray, phi_s: np.ndarray, targets: np.ndarray,
                     compliance: np.ndarray) -> np.ndarray:
    """(F, m) compliant static solution of every frame: q = Λ⁻¹Φᵀ(Φ Λ⁻¹ Φᵀ + C)⁻¹ c.

    Per frame q minimises ½qᵀΛq + Σ_s |Φ_s q - c_s|² / (2 C_s) over the acting
    sensors (finite target and compliance); C = 0 holds a sensor exactly.
    targets : (F, S, 3) m; compliance : (F, S) m/N.  Batched solves of
    :data:`FRAMES_PER_SOLVE` frames.
    """
    lam = np.asarray(eigenvalues, dtype=np.float64)
    out = np.empty((targets.shape[0], len(lam)))
    for frames, mult, phi2 in _compliant_multipliers(lam, phi_s, targets, compliance):
        out[frames] = (mult @ phi2) / lam
    return out


def compliant_targets(eigenvalues: np.ndarray, phi_s: np.ndarray, targets: np.ndarray,
                      compliance: np.ndarray) -> np.ndarray:
    """(F, S, 3) sensor-node displacements Φ_s q̃ of the compliant static solution (:func:`compliant_shapes`).

    The measured targets projected onto the deformations the tongue makes most
    easily, for every sensor (a sensor not acting gets where the others put
    its node).  A hard constraint (C = 0) keeps its target.
    """
    lam = np.asarray(eigenvalues, dtype=np.float64)
    out = np.empty(targets.shape)
    for frames, mult, phi2 in _compliant_multipliers(lam, phi_s, targets, compliance):
        out[frames] = np.einsum("scm,fm->fsc", phi_s, (mult @ phi2) / lam)
    return out


def _compliant_multipliers(lam, phi_s, targets, compliance):
    """Per batch of frames: (frames slice, multipliers (f, 3S), Φ_s as (3S, m)); zero on the sensors not acting."""
    n_frames, n_s, _ = targets.shape
    phi2 = phi_s.reshape(3 * n_s, len(lam))
    gram = (phi2 / lam) @ phi2.T  # (3S, 3S)
    idx = np.arange(3 * n_s)
    compliance = np.broadcast_to(np.asarray(compliance, dtype=np.float64), (n_frames, n_s))
    for start in range(0, n_frames, FRAMES_PER_SOLVE):
        frames = slice(start, min(start + FRAMES_PER_SOLVE, n_frames))
        comp = np.repeat(compliance[frames], 3, axis=1)  # (f, 3S)
        c = targets[frames].reshape(-1, 3 * n_s)
        acting = np.isfinite(comp) & np.isfinite(c)
        acting = np.repeat(np.all(acting.reshape(len(c), n_s, 3), axis=2), 3, axis=1)
        mats = np.where(acting[:, :, None] & acting[:, None, :], gram[None], 0.0)
        mats[:, idx, idx] += np.where(acting, np.where(np.isfinite(comp), comp, 0.0), 1.0)
        rhs = np.where(acting, c, 0.0)
        yield frames, np.linalg.solve(mats, rhs[:, :, None])[:, :, 0], phi2


def _blocks(blocks: np.ndarray) -> np.ndarray:
    """(S, 3, 3) blocks -> (3S, 3S) block-diagonal matrix."""
    n = 3 * len(blocks)
    out = np.zeros((n, n))
    idx = np.arange(n).reshape(-1, 3)
    out[idx[:, :, None], idx[:, None, :]] = blocks
    return out


def solve_small(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve a 3S × 3S system; least squares if sensors are redundant."""
    try:
        return np.linalg.solve(matrix, rhs)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(matrix, rhs, rcond=None)[0]


def solve_frame(q_pred, b, a_inv, beta, stat_scale, phi_s, w_s, q_mat, p_mat, c, compliance, x_start,
                settings: ConstraintSettings):
    """Newton's method for one frame; returns (x, μ, converged, iterations).

    q_pred, b, a_inv : (m,) q*, b and A⁻¹ (A diagonal); beta : q = q* + β x;
    stat_scale : weight of the force balance in the merit (β for the dynamic
    solve, 1/λ₁ for the static one: both make it a modal displacement);
    phi_s, w_s : (S, 3, m) rows of the S active sensors; q_mat, p_mat : their
    (3S, 3S) blocks of Φ_s A⁻¹ Φ_sᵀ and W_s A⁻¹ Φ_sᵀ; c : (S, 3) targets (m);
    compliance : (S,) m/N (0 = hard); x_start : (m,) starting x.
    """
    c = np.asarray(c, dtype=np.float64).ravel()
    n_c, m = len(c), len(b)
    n_s = n_c // 3
    comp = np.repeat(np.asarray(compliance, dtype=np.float64), 3)
    phi2 = phi_s.reshape(n_c, m)
    ws2 = w_s.reshape(n_c, m)
    a_diag = 1.0 / a_inv
    eye3 = np.broadcast_to(np.eye(3), (n_s, 3, 3))
    warping = settings.warping

    def evaluate(x_, mult_):
        q = q_pred + beta * x_
        d = phi_s @ q
        if warping:
            w = w_s @ q
            g, rot, dg = rotate_accumulated_jacobian(w, d)
        else:
            w, g, rot, dg = np.zeros_like(d), d, eye3, np.zeros((n_s, 3, 3))
        rt_mu = np.einsum("sji,sj->si", rot, mult_.reshape(-1, 3)).ravel()
        r_stat = a_diag * x_ - b - phi2.T @ rt_mu
        r_con = c - g.ravel() - comp * mult_
        return r_stat, r_con, _blocks(rot), _blocks(dg), w

    x = np.asarray(x_start, dtype=np.float64).copy()
    _, r_con, rot, dg, w = evaluate(x, np.zeros(n_c))
    # Forces of the problem linearised at the start point (exact if linear):
    # (β J A⁻¹ Φ_sᵀ R̃ᵀ + C) μ = r_con + β J (x - A⁻¹ b).
    h_mat = rot @ q_mat + dg @ p_mat  # J A⁻¹ Φ_sᵀ
    jac_times = lambda v: rot @ (phi2 @ v) + dg @ (ws2 @ v)  # noqa: E731
    rhs = r_con + beta * (jac_times(x) - jac_times(a_inv * b))
    mult = solve_small(beta * h_mat @ rot.T + np.diag(comp), rhs)
    x = a_inv * (b + phi2.T @ (rot.T @ mult))
    if not warping:
        return x, mult, True, 1

    r_stat, r_con, rot, dg, w = evaluate(x, mult)
    merit = np.hypot(np.linalg.norm(stat_scale * r_stat), np.linalg.norm(r_con))
    # The force balance is met to round-off of its own terms (A x and b can be
    # large with few modes), so its tolerance is relative to them.
    tol_stat = settings.tolerance + STATIONARITY_RTOL * stat_scale * max(np.abs(a_diag * x).max(), np.abs(b).max())
    for it in range(1, settings.max_iterations + 1):
        if np.max(np.abs(r_con)) < settings.tolerance and np.max(np.abs(stat_scale * r_stat)) < tol_stat:
            return x, mult, True, it
        # X = ∂(R̃ᵀμ)/∂w; R̃(w)ᵀ = R̃(-w), so X = -∂g/∂w at (-w, μ).
        _, _, dgt = rotate_accumulated_jacobian(-w, mult.reshape(-1, 3))
        x_mat = _blocks(-dgt)
        ar = a_inv * r_stat
        rho_w, rho_p = ws2 @ ar, phi2 @ ar
        e_mat = np.eye(n_c) - beta * x_mat @ p_mat
        sol = solve_small(e_mat, np.column_stack([rot.T, beta * x_mat @ rho_w]))
        e_rt, e_x = sol[:, :n_c], sol[:, n_c]
        h_mat = rot @ q_mat + dg @ p_mat
        d_mult = solve_small(beta * h_mat @ e_rt + np.diag(comp),
                             r_con + beta * (rot @ rho_p + dg @ rho_w) + beta * h_mat @ e_x)
        y = e_rt @ d_mult - e_x
        d_x = a_inv * (phi2.T @ y - r_stat)
        dw = np.abs(beta * (p_mat @ y - rho_w)).max()  # = |W_s β Δx|
        t = min(1.0, MAX_ROTATION_STEP / dw) if dw > 0 else 1.0
        while True:
            trial = (x + t * d_x, mult + t * d_mult)
            rs, rc, rot_t, dg_t, w_t = evaluate(*trial)
            trial_merit = np.hypot(np.linalg.norm(stat_scale * rs), np.linalg.norm(rc))
            if trial_merit < merit or t < 1e-4:
                break
            t *= 0.5
        if not trial_merit < merit:  # never accept a step that raises the residual (or is NaN)
            return x, mult, False, it
        (x, mult), r_stat, r_con, rot, dg, w, merit = trial, rs, rc, rot_t, dg_t, w_t, trial_merit
    done = np.max(np.abs(r_con)) < settings.tolerance and np.max(np.abs(stat_scale * r_stat)) < tol_stat
    return x, mult, bool(done), settings.max_iterations
