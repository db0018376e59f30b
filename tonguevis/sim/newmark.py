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
STATIONARITY_RTOL = 1e-10  # force balance, relative to the size of its terms


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
    n_c = 3 * n_sensors
    phi2 = phi_s.reshape(n_c, m)
    q_full = (phi2 * a_inv) @ phi2.T  # Φ_s A⁻¹ Φ_sᵀ
    p_full = (w_s.reshape(n_c, m) * a_inv) @ phi2.T  # W_s A⁻¹ Φ_sᵀ
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
            rows = (3 * np.flatnonzero(valid)[:, None] + np.arange(3)).ravel()
            blocks = np.ix_(rows, rows)
            qdd_k, converged[i], iterations[i] = _solve_frame(
                q_pred, b, a_inv, bn, phi_s[valid], w_s[valid], q_full[blocks], p_full[blocks],
                targets[i, valid], q, settings,
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


def _blocks(blocks: np.ndarray) -> np.ndarray:
    """(S, 3, 3) blocks -> (3S, 3S) block-diagonal matrix."""
    n = 3 * len(blocks)
    out = np.zeros((n, n))
    idx = np.arange(n).reshape(-1, 3)
    out[idx[:, :, None], idx[:, None, :]] = blocks
    return out


def _solve_frame(q_pred, b, a_inv, bn, phi_s, w_s, q_mat, p_mat, c, q_start, settings):
    """Newton's method for one frame; returns (q̈, converged, iterations).

    Unknowns q̈ and the sensor forces μ (3S) of
        A q̈ = b + Φ_sᵀ R̃_sᵀ μ,   f(q) = R̃(W_s q) Φ_s q = c,   q = q* + β q̈.
    The sensor force is a nodal force, brought into modal space as modal
    warping brings every external force (Choi & Ko 2005: f_q = Φᵀ R̃ᵀ f).
    Using the full constraint gradient J = ∂f/∂q there instead (a textbook
    Lagrange multiplier) adds ∂R̃/∂w terms that push energy into the modes
    with most curl at the sensors; in trials on the ArtiSynth tongue that fed
    a growing oscillation across syllables and let Newton settle on
    large-rotation branches.

    The iteration starts at the previous frame's q with the forces of the
    linearised problem there, then takes full Newton steps (∂R̃/∂w on both
    equations), caps the change of the sensor rotations per step and
    backtracks on the residual norm, never accepting a step that raises it.
    Every product with the m modes is folded into the constant 3S × 3S
    matrices Q = Φ_s A⁻¹ Φ_sᵀ and P = W_s A⁻¹ Φ_sᵀ (``q_mat``, ``p_mat``):
    with y = β X W_s Δq̈ + R̃ᵀΔμ the Newton system
        (A - β Φ_sᵀ X W_s) Δq̈ - Φ_sᵀ R̃ᵀ Δμ = -r_stat,   β (R̃ Φ_s + D W_s) Δq̈ = r_con
    becomes Δq̈ = A⁻¹(Φ_sᵀ y - r_stat) and two 3S × 3S solves, where D = ∂g/∂w
    and X = ∂(R̃ᵀμ)/∂w (both block diagonal).
    """
    c = c.ravel()
    n_c, m = len(c), len(b)
    n_s = n_c // 3
    phi2 = phi_s.reshape(n_c, m)
    ws2 = w_s.reshape(n_c, m)
    a_diag = 1.0 / a_inv
    eye3 = np.broadcast_to(np.eye(3), (n_s, 3, 3))

    def evaluate(qdd_, mult_):
        q = q_pred + bn * qdd_
        d = phi_s @ q
        if settings.warping:
            w = w_s @ q
            g, rot, dg = rotate_accumulated_jacobian(w, d)
        else:
            w, g, rot, dg = np.zeros_like(d), d, eye3, np.zeros((n_s, 3, 3))
        rt_mu = np.einsum("sji,sj->si", rot, mult_.reshape(-1, 3)).ravel()
        r_stat = a_diag * qdd_ - b - phi2.T @ rt_mu
        r_con = c - g.ravel()
        return r_stat, r_con, _blocks(rot), _blocks(dg), w

    qdd = (q_start - q_pred) / bn
    _, r_con, rot, dg, w = evaluate(qdd, np.zeros(n_c))
    # Forces of the linearised problem at the start point (exact if linear): β J A⁻¹ Gᵀ μ = ...
    h_mat = rot @ q_mat + dg @ p_mat  # J A⁻¹ Φ_sᵀ
    jac_times = lambda v: rot @ (phi2 @ v) + dg @ (ws2 @ v)  # noqa: E731
    rhs = r_con + bn * (jac_times(qdd) - jac_times(a_inv * b))
    mult = _solve_small(bn * h_mat @ rot.T, rhs)
    qdd = a_inv * (b + phi2.T @ (rot.T @ mult))
    if not settings.warping:
        return qdd, True, 1

    r_stat, r_con, rot, dg, w = evaluate(qdd, mult)
    merit = np.hypot(np.linalg.norm(bn * r_stat), np.linalg.norm(r_con))
    # The force balance is met to round-off of its own terms (β A q̈ and β b can
    # be large with few modes), so its tolerance is relative to them.
    tol_stat = settings.tolerance + STATIONARITY_RTOL * bn * max(np.abs(a_diag * qdd).max(), np.abs(b).max())
    for it in range(1, settings.max_iterations + 1):
        if np.max(np.abs(r_con)) < settings.tolerance and np.max(np.abs(bn * r_stat)) < tol_stat:
            return qdd, True, it
        # X = ∂(R̃ᵀμ)/∂w; R̃(w)ᵀ = R̃(-w), so X = -∂g/∂w at (-w, μ).
        _, _, dgt = rotate_accumulated_jacobian(-w, mult.reshape(-1, 3))
        x_mat = _blocks(-dgt)
        ar = a_inv * r_stat
        rho_w, rho_p = ws2 @ ar, phi2 @ ar
        e_mat = np.eye(n_c) - bn * x_mat @ p_mat
        sol = _solve_small(e_mat, np.column_stack([rot.T, bn * x_mat @ rho_w]))
        e_rt, e_x = sol[:, :n_c], sol[:, n_c]
        h_mat = rot @ q_mat + dg @ p_mat
        d_mult = _solve_small(bn * h_mat @ e_rt, r_con + bn * (rot @ rho_p + dg @ rho_w) + bn * h_mat @ e_x)
        y = e_rt @ d_mult - e_x
        d_qdd = a_inv * (phi2.T @ y - r_stat)
        dw = np.abs(bn * (p_mat @ y - rho_w)).max()  # = |W_s β Δq̈|
        t = min(1.0, MAX_ROTATION_STEP / dw) if dw > 0 else 1.0
        while True:
            trial = (qdd + t * d_qdd, mult + t * d_mult)
            rs, rc, rot_t, dg_t, w_t = evaluate(*trial)
            trial_merit = np.hypot(np.linalg.norm(bn * rs), np.linalg.norm(rc))
            if trial_merit < merit or t < 1e-4:
                break
            t *= 0.5
        if trial_merit >= merit:  # never accept a step that raises the residual
            return qdd, False, it
        (qdd, mult), r_stat, r_con, rot, dg, w, merit = trial, rs, rc, rot_t, dg_t, w_t, trial_merit
    done = np.max(np.abs(r_con)) < settings.tolerance and np.max(np.abs(bn * r_stat)) < tol_stat
    return qdd, bool(done), settings.max_iterations


def _solve_small(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve the 3S × 3S Schur system; least squares if sensors are redundant."""
    try:
        return np.linalg.solve(matrix, rhs)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(matrix, rhs, rcond=None)[0]
