"""Quasi-static solve of the modal model held to sensor targets (a validation baseline).

The same model and constraint as :mod:`tonguevis.sim.newmark`, with inertia
and damping dropped: each frame independently solves

    Λ q = Φ_sᵀ R̃_sᵀ μ,    f(q) = R̃(W_s q) Φ_s q = c,

the stiffness balancing the warped nodal sensor forces (the force model of
the dynamic integrator), with Newton's method from the previous frame's
solution (full Jacobian including ∂R̃/∂w on both equations, dense
(m + 3S)² solve), the sensor rotation step capped and a backtracking line
search that never accepts a step raising the residual.  Without warping the
solution has the closed form q = Λ⁻¹Φ_sᵀ (Φ_s Λ⁻¹ Φ_sᵀ)⁻¹ c
(:func:`linear_static`), all frames at once.
"""

from __future__ import annotations

import numpy as np

from tonguevis.sim.rotation import rotate_accumulated_jacobian

MAX_ROTATION_STEP = 0.5  # rad per Newton step, as the dynamic integrator


def linear_static(eigenvalues: np.ndarray, phi_s: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(F, m) minimum-energy q with Φ_s q = c for targets (F, S, 3) (no NaN), metres."""
    lam = np.asarray(eigenvalues, dtype=np.float64)
    phi2 = phi_s.reshape(-1, len(lam))
    gram = (phi2 / lam) @ phi2.T
    mult = np.linalg.solve(gram, targets.reshape(len(targets), -1).T)  # (3S, F)
    return ((phi2.T @ mult) / lam[:, None]).T


def quasi_static(eigenvalues, phi_s, w_s, targets, tolerance: float = 1e-8, max_iterations: int = 30):
    """Warped quasi-static solution per frame.

    eigenvalues : (m,) Λ in s⁻²; phi_s, w_s : (S, 3, m) sensor rows of Φ and W;
    targets : (F, S, 3) sensor displacements (m), NaN = missing (that sensor is
    dropped in that frame; a frame with none relaxes to q = 0).
    Returns (q (F, m), converged (F,) bool, iterations (F,) int).
    """
    lam = np.asarray(eigenvalues, dtype=np.float64)
    m = len(lam)
    n_frames = len(targets)
    out = np.zeros((n_frames, m))
    converged = np.zeros(n_frames, dtype=bool)
    iterations = np.zeros(n_frames, dtype=np.int64)
    q = np.zeros(m)
    mults: dict[tuple, np.ndarray] = {}
    for i in range(n_frames):
        valid = np.all(np.isfinite(targets[i]), axis=1)
        if not valid.any():
            q = np.zeros(m)
            converged[i] = True
            out[i] = q
            continue
        key = tuple(valid)
        mult = mults.get(key, np.zeros(3 * int(valid.sum())))
        q, mult, converged[i], iterations[i] = _solve_frame(
            lam, phi_s[valid], w_s[valid], targets[i, valid].ravel(), q, mult, tolerance, max_iterations)
        mults[key] = mult
        out[i] = q
    return out, converged, iterations


def _solve_frame(lam, phi_s, w_s, c, q, mult, tolerance, max_iterations):
    n_s = len(phi_s)
    n_c, m = 3 * n_s, len(lam)
    phi2, ws2 = phi_s.reshape(n_c, m), w_s.reshape(n_c, m)
    scale = 1.0 / lam[0]  # stationarity residual in units of q

    def evaluate(q_, mult_):
        w = w_s @ q_
        g, rot, dg = rotate_accumulated_jacobian(w, phi_s @ q_)
        rt_mu = np.einsum("sji,sj->si", rot, mult_.reshape(n_s, 3)).ravel()
        r_stat = scale * (lam * q_ - phi2.T @ rt_mu)
        r_con = c - g.ravel()
        return r_stat, r_con, rot, dg, w

    r_stat, r_con, rot, dg, w = evaluate(q, mult)
    merit = np.hypot(np.linalg.norm(r_stat), np.linalg.norm(r_con))
    for it in range(max_iterations + 1):
        if np.max(np.abs(r_con)) < tolerance and np.max(np.abs(r_stat)) < tolerance:
            return q, mult, True, it
        if it == max_iterations:
            break
        _, _, dgt = rotate_accumulated_jacobian(-w, mult.reshape(n_s, 3))  # ∂(R̃ᵀμ)/∂w = -∂g/∂w at (-w, μ)
        x_w = np.einsum("sij,sjm->sim", -dgt, w_s).reshape(n_c, m)
        g_mat = np.einsum("sij,sjm->sim", rot, phi_s).reshape(n_c, m)  # R̃ Φ_s
        jac = g_mat + np.einsum("sij,sjm->sim", dg, w_s).reshape(n_c, m)
        # Newton system  scale (Λ - Φ_sᵀ X W_s) Δq - scale Gᵀ Δμ = -r_stat,  J Δq = r_con,
        # with the stiffness block inverted by Woodbury (diagonal Λ minus rank 3S):
        # (Λ - Φ_sᵀ X_w)⁻¹ B = Λ⁻¹B + Λ⁻¹Φ_sᵀ (I - X_w Λ⁻¹ Φ_sᵀ)⁻¹ X_w Λ⁻¹ B.
        lam_inv_u = phi2.T / lam[:, None]  # (m, 3S)
        core = np.eye(n_c) - x_w @ lam_inv_u
        rhs = np.column_stack([g_mat.T, -r_stat / scale])  # (m, 3S + 1)
        y = rhs / lam[:, None]
        sol = y + lam_inv_u @ _solve_small(core, x_w @ y)
        t_g, t_r = sol[:, :n_c], sol[:, n_c]  # K⁻¹Gᵀ, K⁻¹(-r_stat)/scale
        d_mult = _solve_small(jac @ t_g, r_con - jac @ t_r)
        d_q = t_g @ d_mult + t_r
        dw = np.abs(ws2 @ d_q).max()
        t = min(1.0, MAX_ROTATION_STEP / dw) if dw > 0 else 1.0
        while True:
            trial = (q + t * d_q, mult + t * d_mult)
            rs, rc, rot_t, dg_t, w_t = evaluate(*trial)
            trial_merit = np.hypot(np.linalg.norm(rs), np.linalg.norm(rc))
            if trial_merit < merit or t < 1e-4:
                break
            t *= 0.5
        if trial_merit >= merit:
            return q, mult, False, it + 1
        (q, mult), r_stat, r_con, rot, dg, w, merit = trial, rs, rc, rot_t, dg_t, w_t, trial_merit
    return q, mult, False, max_iterations


def _solve_small(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    try:
        return np.linalg.solve(matrix, rhs)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(matrix, rhs, rcond=None)[0]
