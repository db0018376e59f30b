"""Newmark integration of the modal model with warped sensor constraints.

Per frame (step h), with the average-acceleration predictors of the paper (§4)
q* = q + h q̇ + h²/4 q̈ and q̇* = q̇ + h/2 q̈, the new state is
q = q* + β q̈ (β = h²/4), q̇ = q̇* + h/2 q̈, where q̈ solves

    A q̈ = b + Jᵀ μ,   f(q* + β q̈) = c,

A = I + h/2 C_q + β Λ (diagonal), b = -C_q q̇* - Λ q*, and f(q) the warped
positions of the sensor nodes relative to rest, f(q) = R̃(W_s q) Φ_s q.  The
constraint is nonlinear in q, so it is solved by Newton's method from the
previous frame: each iterate linearises f (the Jacobian includes ∂R̃/∂w, see
:func:`rotation.rotate_accumulated_jacobian`) and solves the KKT system by a
Schur complement on the 3S multipliers.  Safeguards: the step of the sensor
rotations is capped, a backtracking line search never accepts a step that
raises the constraint residual, and frames that do not converge are flagged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.sim.rotation import rotate_accumulated_jacobian

MAX_ROTATION_STEP = 0.5  # rad: largest change of a sensor node's rotation vector per Newton step


@dataclass
class NewmarkSettings:
    """Integrator settings.

    dt : time step h in s.
    alpha, beta : Rayleigh damping, C_q = α I + β Λ.
    tolerance : constraint residual (m, max over sensor coordinates) to stop Newton.
    max_iterations : Newton iterations per frame.
    warping : whether the constraint holds the warped (True) or linear positions.
    """

    dt: float
    alpha: float
    beta: float
    tolerance: float = 1e-8
    max_iterations: int = 20
    warping: bool = True


@dataclass
class IntegrationResult:
    """q, q̇, q̈ (F, m); residual (F, S) in m; converged (F,); iterations (F,)."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    residual: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray


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


def integrate(
    eigenvalues: np.ndarray,
    phi_s: np.ndarray,
    w_s: np.ndarray,
    targets: np.ndarray,
    settings: NewmarkSettings,
    progress: ProgressCallback | None = None,
) -> IntegrationResult:
    """Integrate all frames; ``targets`` (F, S, 3) are sensor displacements from rest (m), NaN = missing.

    The first frame starts from rest (q = q̇ = q̈ = 0 before it).
    """
    lam = np.asarray(eigenvalues, dtype=np.float64)
    m = len(lam)
    n_frames, n_sensors, _ = targets.shape
    h = settings.dt
    bn = h * h / 4.0
    damp = settings.alpha + settings.beta * lam
    a_inv = 1.0 / (1.0 + 0.5 * h * damp + bn * lam)
    q = np.zeros(m)
    qd = np.zeros(m)
    qdd = np.zeros(m)
    out_q = np.empty((n_frames, m))
    out_qd = np.empty((n_frames, m))
    out_qdd = np.empty((n_frames, m))
    residual = np.full((n_frames, n_sensors), np.nan)
    converged = np.zeros(n_frames, dtype=bool)
    iterations = np.zeros(n_frames, dtype=np.int64)
    every = max(1, n_frames // 100)
    for i in range(n_frames):
        q_pred = q + h * qd + bn * qdd
        qd_pred = qd + 0.5 * h * qdd
        b = -damp * qd_pred - lam * q_pred
        valid = np.all(np.isfinite(targets[i]), axis=1)
        free_qdd = a_inv * b
        if not valid.any():
            qdd_k = free_qdd
            converged[i] = True
        else:
            qdd_k, converged[i], iterations[i] = _solve_frame(
                q_pred, b, a_inv, bn, phi_s[valid], w_s[valid], targets[i, valid], q, settings
            )
        q = q_pred + bn * qdd_k
        qd = qd_pred + 0.5 * h * qdd_k
        qdd = qdd_k
        out_q[i], out_qd[i], out_qdd[i] = q, qd, qdd
        f, _ = sensor_constraint(q, phi_s, w_s, settings.warping)
        residual[i] = np.linalg.norm(f - targets[i], axis=1)
        if i % every == 0:
            report(progress, i, n_frames, "integrating")
    report(progress, n_frames, n_frames, "integrated")
    return IntegrationResult(out_q, out_qd, out_qdd, residual, converged, iterations)


def _solve_frame(q_pred, b, a_inv, bn, phi_s, w_s, c, q_start, settings):
    """Newton's method for one frame; returns (q̈, converged, iterations).

    Unknowns q̈ and the sensor forces μ (3S) of
        A q̈ = b + Φ_sᵀ R̃_sᵀ μ,   f(q) = R̃(W_s q) Φ_s q = c,   q = q* + β q̈.
    The sensor force is a nodal force, brought into modal space as modal
    warping brings every external force (Choi & Ko 2005: f_q = Φᵀ R̃ᵀ f).
    Using the full constraint gradient J = ∂f/∂q there instead (a textbook
    Lagrange multiplier) adds ∂R̃/∂w terms that push energy into the modes
    with most curl at the sensors; in trials on the ArtiSynth tongue that fed
    a growing oscillation across syllables and let Newton settle on
    large-rotation branches.  The iteration starts at the previous frame's q,
    takes full Newton steps (the Jacobian includes ∂R̃/∂w on both equations),
    caps the change of the sensor rotations per step, and backtracks on the
    residual norm, never accepting a step that raises it.
    """
    c = c.ravel()
    m = len(b)
    n_c = len(c)
    qdd = (q_start - q_pred) / bn
    a_diag = 1.0 / a_inv

    def evaluate(qdd_, mult_):
        q = q_pred + bn * qdd_
        d = phi_s @ q
        if settings.warping:
            w = w_s @ q
            g, rot, dg_dw = rotate_accumulated_jacobian(w, d)
            jac = (rot @ phi_s + dg_dw @ w_s).reshape(n_c, m)
            force_map = (rot @ phi_s).reshape(n_c, m)  # G = R̃_s Φ_s
        else:
            g, jac, force_map = d, phi_s.reshape(n_c, m), phi_s.reshape(n_c, m)
            w = None
        r_stat = a_diag * qdd_ - b - force_map.T @ mult_
        r_con = c - g.ravel()
        return r_stat, r_con, jac, force_map, w

    # Forces of the linearised problem at the start point (exact if linear).
    _, r_con, jac, force_map, _ = evaluate(qdd, np.zeros(n_c))
    ga = force_map * a_inv
    rhs = r_con + bn * (jac @ qdd) - bn * (jac @ (a_inv * b))
    mult = _solve_small(bn * (jac * a_inv) @ force_map.T, rhs)
    qdd = a_inv * (b + force_map.T @ mult)
    if not settings.warping:
        return qdd, True, 1
    del ga

    r_stat, r_con, jac, force_map, w = evaluate(qdd, mult)
    merit = np.hypot(np.linalg.norm(bn * r_stat), np.linalg.norm(r_con))
    for it in range(1, settings.max_iterations + 1):
        if np.max(np.abs(r_con)) < settings.tolerance and np.max(np.abs(bn * r_stat)) < settings.tolerance:
            return qdd, True, it
        # ∂(R̃ᵀμ)/∂w: R̃(w)ᵀ = R̃(-w), so it is -∂g/∂w at (-w, μ).
        _, _, dgt = rotate_accumulated_jacobian(-w, mult.reshape(-1, 3))
        d_qdd, d_mult = _newton_step(a_inv, bn, phi_s, w_s, -dgt, jac, force_map, r_stat, r_con)
        dw = np.abs(w_s @ (bn * d_qdd)).max()
        t = min(1.0, MAX_ROTATION_STEP / dw) if dw > 0 else 1.0
        while True:
            trial = (qdd + t * d_qdd, mult + t * d_mult)
            rs, rc, jac_t, fm_t, w_t = evaluate(*trial)
            trial_merit = np.hypot(np.linalg.norm(bn * rs), np.linalg.norm(rc))
            if trial_merit < merit or t < 1e-4:
                break
            t *= 0.5
        if trial_merit >= merit:  # never accept a step that raises the residual
            return qdd, False, it
        (qdd, mult), r_stat, r_con, jac, force_map, w, merit = trial, rs, rc, jac_t, fm_t, w_t, trial_merit
    done = np.max(np.abs(r_con)) < settings.tolerance and np.max(np.abs(bn * r_stat)) < settings.tolerance
    return qdd, bool(done), settings.max_iterations


def _newton_step(a_inv, bn, phi_s, w_s, coupling_blocks, jac, force_map, r_stat, r_con):
    """Solve the frame's Newton system with only 3S × 3S dense solves.

        T Δq̈ - Gᵀ Δμ = -r_stat,   β J Δq̈ = r_con,   T = A - β Φ_sᵀ X W_s,

    with A diagonal and X block diagonal (one 3×3 block per sensor,
    ``coupling_blocks`` (S, 3, 3)).  T⁻¹ comes from the Woodbury identity in
    the form that never inverts X (which may be singular):
    T⁻¹ = A⁻¹ - A⁻¹U C (I + V A⁻¹ U C)⁻¹ V A⁻¹, U = Φ_sᵀ, C = -βX, V = W_s.
    """
    n_c = jac.shape[0]
    u = phi_s.reshape(n_c, -1).T  # (m, 3S)
    v = w_s.reshape(n_c, -1)  # (3S, m)
    c = np.zeros((n_c, n_c))
    for k, block in enumerate(coupling_blocks):
        c[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = -bn * block
    ainv_u_c = (a_inv[:, None] * u) @ c  # (m, 3S)
    core = np.eye(n_c) + (v * a_inv) @ u @ c

    def t_inv(y):
        ay = a_inv[:, None] * y
        return ay - ainv_u_c @ _solve_small(core, v @ ay)

    sol = t_inv(np.column_stack([force_map.T, r_stat]))  # T⁻¹ [Gᵀ, r_stat]
    tg, tr = sol[:, :n_c], sol[:, n_c]
    d_mult = _solve_small(bn * jac @ tg, r_con + bn * jac @ tr)
    return tg @ d_mult - tr, d_mult


def _solve_small(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve the 3S × 3S Schur system; least squares if sensors are redundant."""
    try:
        return np.linalg.solve(matrix, rhs)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(matrix, rhs, rcond=None)[0]
