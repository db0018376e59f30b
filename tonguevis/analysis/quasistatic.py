"""Quasi-static solve of the modal model held to sensor targets (a validation baseline).

The same model and constraint as the dynamic integrator with inertia and
damping dropped: each frame solves

    Λ q = Φ_sᵀ R̃_sᵀ μ,    R̃(W_s q) Φ_s q + C μ = c,

by the shared Newton solve of :mod:`tonguevis.sim.constrained` (x = q, A = Λ,
b = 0, q* = 0, β = 1) started from the previous frame's solution.  Without
warping the solution has the closed form q = Λ⁻¹Φ_sᵀ (Φ_s Λ⁻¹ Φ_sᵀ + C)⁻¹ c
(:func:`linear_static`), all frames at once.
"""

from __future__ import annotations

import numpy as np

from tonguevis.sim.constrained import ConstraintSettings, solve_frame


def linear_static(eigenvalues: np.ndarray, phi_s: np.ndarray, targets: np.ndarray,
                  compliance: float = 0.0) -> np.ndarray:
    """(F, m) q minimising ½qᵀΛq + (1/2C)|Φ_s q - c|² (Φ_s q = c when C = 0) for targets (F, S, 3), no NaN."""
    lam = np.asarray(eigenvalues, dtype=np.float64)
    phi2 = phi_s.reshape(-1, len(lam))
    gram = (phi2 / lam) @ phi2.T + compliance * np.eye(len(phi2))
    mult = np.linalg.solve(gram, targets.reshape(len(targets), -1).T)  # (3S, F)
    return ((phi2.T @ mult) / lam[:, None]).T


def quasi_static(eigenvalues, phi_s, w_s, targets, tolerance: float = 1e-8, max_iterations: int = 30,
                 compliance: np.ndarray | float = 0.0, warping: bool = True):
    """Quasi-static solution per frame.

    eigenvalues : (m,) Λ in s⁻²; phi_s, w_s : (S, 3, m) sensor rows of Φ and W;
    targets : (F, S, 3) sensor displacements (m), NaN = missing (that sensor is
    dropped in that frame; a frame with none relaxes to q = 0);
    compliance : (F, S) or scalar, m/N (0 = hard, inf = not acting).
    Returns (q (F, m), converged (F,) bool, iterations (F,) int).
    """
    lam = np.asarray(eigenvalues, dtype=np.float64)
    m = len(lam)
    n_frames, n_sensors, _ = targets.shape
    comp = np.broadcast_to(np.asarray(compliance, dtype=np.float64), (n_frames, n_sensors))
    settings = ConstraintSettings(tolerance, max_iterations, warping)
    a_inv = 1.0 / lam
    phi2 = phi_s.reshape(-1, m)
    q_full = (phi2 * a_inv) @ phi2.T
    p_full = (w_s.reshape(-1, m) * a_inv) @ phi2.T
    zeros = np.zeros(m)
    out = np.zeros((n_frames, m))
    converged = np.zeros(n_frames, dtype=bool)
    iterations = np.zeros(n_frames, dtype=np.int64)
    q = zeros
    for i in range(n_frames):
        active = np.all(np.isfinite(targets[i]), axis=1) & np.isfinite(comp[i])
        if not active.any():
            q, converged[i] = zeros, True
        else:
            rows = (3 * np.flatnonzero(active)[:, None] + np.arange(3)).ravel()
            blocks = np.ix_(rows, rows)
            q, _, converged[i], iterations[i] = solve_frame(
                zeros, zeros, a_inv, 1.0, 1.0 / lam[0], phi_s[active], w_s[active], q_full[blocks],
                p_full[blocks], targets[i, active], comp[i, active], q, settings)
        out[i] = q
    return out, converged, iterations
