"""Newmark integration of the modal model with (compliant) warped sensor constraints.

Per frame (step h), with the average-acceleration predictors of the paper (§4)
q* = q + h q̇ + h²/4 q̈ and q̇* = q̇ + h/2 q̈, the new state is
q = q* + β q̈ (β = h²/4), q̇ = q̇* + h/2 q̈, where q̈ solves

    A q̈ = b + Φ_sᵀ R̃_sᵀ μ,   R̃(W_s q) Φ_s q + C μ = c,

A = I + h/2 C_q + β Λ (diagonal), b = -C_q q̇* - Λ q*, by the shared Newton
solve of :mod:`tonguevis.sim.constrained`.  C (m/N, per sensor and frame) is 0
for the paper's hard constraints; a sensor whose target is NaN or whose
compliance is infinite does not act in that frame.

A frame whose Newton solve does not converge keeps its last iterate (the
line search never raised the residual) and is flagged in ``converged``.  A
frame that is not finite, or whose sensor nodes rotate past
``RUNAWAY_ROTATION`` (a branch no tongue takes), is *recovered*: it keeps the
previous frame's shape and the velocity is reset (q̇ = q̈ = 0), so one bad
frame cannot feed the next; such frames are flagged in ``recovered``.

When a sensor stops acting, the velocity is re-estimated from the last two
shapes, (q_n - q_{n-1})/h, and the acceleration set to zero.  The average
acceleration rule holds positions to hard constraints exactly but lets the
velocity and acceleration along the constrained directions carry an error
that alternates in sign from frame to frame (and grows, for the
acceleration): harmless while the constraint holds, an impulse the moment it
lets go (on a real /ta/ the shape jumped to 1-2.5 rad rotations in the frame a
lost sensor was released).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.sim.constrained import (
    RUNAWAY_ROTATION, ConstraintSettings, sensor_constraint, solve_frame,
)

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

    @property
    def constraint(self) -> ConstraintSettings:
        return ConstraintSettings(self.tolerance, self.max_iterations, self.warping)


@dataclass
class IntegrationResult:
    """q, q̇, q̈ (F, m) (q̇ and q̈ None when the compiled integrator was told not to keep them,
    ``rates=False``); residual (F, S) |f(q) - c| in m; converged (F,); iterations (F,);
    recovered (F,) frames that took the linear fallback (see the module docstring)."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    residual: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    recovered: np.ndarray


def integrate(
    eigenvalues: np.ndarray,
    phi_s: np.ndarray,
    w_s: np.ndarray,
    targets: np.ndarray,
    settings: NewmarkSettings,
    compliance: np.ndarray | float = 0.0,
    external: np.ndarray | None = None,
    progress: ProgressCallback | None = None,
) -> IntegrationResult:
    """Integrate all frames (the NumPy reference of :mod:`newmark_kernel`).

    targets : (F, S, 3) sensor displacements from rest (m), NaN = missing.
    compliance : (F, S) or a scalar, m/N; 0 = hard, inf = the sensor does not act.
    external : (F, m) external modal forces (e.g. the palate's contact forces), or None.
    The first frame starts from rest (q = q̇ = q̈ = 0 before it).
    """
    lam = np.asarray(eigenvalues, dtype=np.float64)
    m = len(lam)
    n_frames, n_sensors, _ = targets.shape
    comp = np.broadcast_to(np.asarray(compliance, dtype=np.float64), (n_frames, n_sensors))
    ext = np.zeros((n_frames, m)) if external is None else np.asarray(external, dtype=np.float64)
    h = settings.dt
    bn = h * h / 4.0
    damp = settings.alpha + settings.beta * lam
    a_inv = 1.0 / (1.0 + 0.5 * h * damp + bn * lam)
    constraint = settings.constraint
    q = np.zeros(m)
    qd = np.zeros(m)
    qdd = np.zeros(m)
    out_q = np.empty((n_frames, m))
    out_qd = np.empty((n_frames, m))
    out_qdd = np.empty((n_frames, m))
    residual = np.full((n_frames, n_sensors), np.nan)
    converged = np.zeros(n_frames, dtype=bool)
    recovered = np.zeros(n_frames, dtype=bool)
    iterations = np.zeros(n_frames, dtype=np.int64)
    n_c = 3 * n_sensors
    phi2 = phi_s.reshape(n_c, m)
    ws2 = w_s.reshape(n_c, m)
    q_full = (phi2 * a_inv) @ phi2.T  # Φ_s A⁻¹ Φ_sᵀ
    p_full = (ws2 * a_inv) @ phi2.T  # W_s A⁻¹ Φ_sᵀ
    every = max(1, n_frames // 100)
    q_prev = np.zeros(m)
    was_active = np.zeros(n_sensors, dtype=bool)
    for i in range(n_frames):
        active = np.all(np.isfinite(targets[i]), axis=1) & np.isfinite(comp[i])
        if i > 0 and np.any(was_active & ~active):
            qd, qdd = (q - q_prev) / h, np.zeros(m)  # a sensor let go: see the module docstring
        q_pred = q + h * qd + bn * qdd
        qd_pred = qd + 0.5 * h * qdd
        b = -damp * qd_pred - lam * q_pred + ext[i]
        q_prev, was_active = q, active
        if not active.any():
            qdd_k = a_inv * b
            converged[i] = True
        else:
            rows = (3 * np.flatnonzero(active)[:, None] + np.arange(3)).ravel()
            blocks = np.ix_(rows, rows)
            args = (q_pred, b, a_inv, bn, bn, phi_s[active], w_s[active], q_full[blocks], p_full[blocks],
                    targets[i, active], comp[i, active], (q - q_pred) / bn)
            qdd_k, _, converged[i], iterations[i] = solve_frame(*args, constraint)
            q_new = q_pred + bn * qdd_k
            if not (np.all(np.isfinite(q_new))
                    and (not settings.warping or _largest_rotation(ws2, q_new) <= RUNAWAY_ROTATION)):
                qdd_k = (q - q_pred) / bn  # the previous frame's shape, at rest
                recovered[i] = True
        q = q_pred + bn * qdd_k
        if recovered[i]:
            qd, qdd = np.zeros(m), np.zeros(m)
        else:
            qd = qd_pred + 0.5 * h * qdd_k
            qdd = qdd_k
        out_q[i], out_qd[i], out_qdd[i] = q, qd, qdd
        f, _ = sensor_constraint(q, phi_s, w_s, settings.warping)
        residual[i] = np.linalg.norm(f - targets[i], axis=1)
        if i % every == 0:
            report(progress, i, n_frames, "integrating")
    report(progress, n_frames, n_frames, "integrated")
    return IntegrationResult(out_q, out_qd, out_qdd, residual, converged, iterations, recovered)


def _largest_rotation(ws2: np.ndarray, q: np.ndarray) -> float:
    """Largest |w| (rad) over the sensor nodes of rows W_s (3S, m) at q."""
    return float(np.linalg.norm((ws2 @ q).reshape(-1, 3), axis=1).max())

