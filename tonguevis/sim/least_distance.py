"""Least distance programming: the shortest z with ``g @ z >= h``, the problem each pass of the humps' projection
below the palate solves (:mod:`tonguevis.sim.patch_contact`).

:func:`least_distance` is the plain one (one NNLS, Lawson & Hanson); :func:`least_distance_from` the fast one, the
dual active set method of Goldfarb & Idnani (1983, "A numerically stable dual method for solving strictly convex
quadratic programs", Math. Programming 27) with the identity for the Hessian, started from the active set and
multipliers of the problem before (the projection's passes only add rows to their problem, so the last pass's
solution is optimal for the rows it had: a valid start, and a pass then adds the few rows its new linearisation
violates).  It returns None when it cannot answer cleanly (no progress within its steps, rows nearly dependent
on the active ones with no multiplier to release: maybe infeasible), and the caller asks the NNLS.
The projection runs it compiled (:mod:`tonguevis.sim.least_distance_kernel`, many problems a launch); this is its
readable form, step by step the same.
"""

from __future__ import annotations

import numpy as np

#: A row counts as satisfied within this fraction of max |h| (rounding: the NNLS's own answer is no closer).
FEASIBLE = 1e-12
#: A row joins the active set only if its component off the active rows' span keeps this fraction of its squared
#: norm (sin² of the angle): nearer, the active rows' Gram matrix loses digits, and the NNLS takes the problem.
INDEPENDENT = 1e-8
#: Multipliers the final polish may leave this far below zero (relative to the largest; a degenerate row).
NEGATIVE = 1e-9
MAX_STEPS = 64


def least_distance(g: np.ndarray, h: np.ndarray) -> np.ndarray | None:
    """The shortest z with ``g @ z >= h`` (g (a, n), h (a,)), None if there is none: least distance
    programming by one NNLS (Lawson & Hanson 1974, "Solving Least Squares Problems", ch. 23)."""
    from scipy.optimize import nnls

    n = g.shape[1]
    e = np.vstack([g.T, h[None]])
    f = np.zeros(n + 1)
    f[n] = 1.0
    u = nnls(e, f, maxiter=50 * max(len(h), 1))[0]
    r = e @ u - f
    if not np.isfinite(r).all() or abs(r[n]) < 1e-12:
        return None
    return -r[:n] / r[n]


def least_distance_from(g: np.ndarray, h: np.ndarray, active: np.ndarray, weights: np.ndarray,
                        max_steps: int = MAX_STEPS) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(z, active rows, their multipliers) of the shortest z with ``g @ z >= h`` (g (a, n), h (a,)), or None (ask
    :func:`least_distance`).

    active : (s,) rows and weights (s,) >= 0 their multipliers, optimal for the problem on those rows alone
    (z = g[active]ᵀ weights with g[active] z = h[active]: e.g. the answer of the problem before a pass added
    rows; empty: z = 0).  Goldfarb-Idnani: the most violated row p joins; the step
    moves z along p's row off the active rows' span, releasing an active row whose multiplier reaches zero
    first, until p holds.  The inverse of the active rows' Gram matrix is updated by its Schur complement on each
    change; the answer is polished from the final set (its equalities solved afresh, as the NNLS's own polish
    does) and checked: every row satisfied to :data:`FEASIBLE`, no multiplier below zero beyond rounding, so it
    is the one optimum (the objective is strictly convex) to rounding."""
    g = np.asarray(g, dtype=np.float64)
    h = np.asarray(h, dtype=np.float64)
    s = len(active)
    tol = FEASIBLE * max(float(np.abs(h).max()) if h.size else 0.0, 1e-300)
    cap = min(len(h), g.shape[1]) + 1  # at most n independent rows are active (and one joining)
    if s >= cap:
        return None
    rows_at = np.empty(cap, dtype=np.int64)  # the active rows, their multipliers, g's rows, Gram inverse
    v, ga, inverse = np.empty(cap), np.empty((cap, g.shape[1])), np.empty((cap, cap))
    rows_at[:s], v[:s], ga[:s] = active, weights, g[active]
    try:
        inverse[:s, :s] = np.linalg.inv(ga[:s] @ ga[:s].T) if s else 0.0
    except np.linalg.LinAlgError:
        return None
    z = v[:s] @ ga[:s]
    p = -1
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(max_steps):
            if p < 0:  # the most violated row joins
                w = g @ z - h
                p = int(np.argmin(w))
                if w[p] >= -tol:
                    return _polished(g, h, rows_at[:s].copy(), tol)
                row, slack, vp = g[p], float(w[p]), 0.0
                norm2 = float(row @ row)
            r = inverse[:s, :s] @ (ga[:s] @ row)  # the active multipliers' change per unit of p's
            d = row - r @ ga[:s]  # z's, off the active rows' span
            dd = float(d @ d)
            full = -slack / dd if dd > INDEPENDENT * norm2 else np.inf
            release, j = np.inf, -1
            if s:
                ratio = np.where(r > 0, v[:s] / r, np.inf)
                j = int(np.argmin(ratio))
                release = float(ratio[j])
            if not (full < np.inf or release < np.inf):
                return None  # p's row dependent on the active ones, none to release: perhaps infeasible
            t = min(full, release)
            z = z + t * d
            v[:s] -= t * r
            vp += t
            if full <= release:  # p holds: it joins (the Gram inverse bordered: Schur complement dd)
                if s + 1 >= cap:
                    return None
                inverse[:s, :s] += np.outer(r, r) / dd
                inverse[s, :s] = inverse[:s, s] = -r / dd
                inverse[s, s] = 1.0 / dd
                rows_at[s], v[s], ga[s] = p, vp, row
                s += 1
                p = -1
            else:  # j's multiplier reached zero: it leaves (swapped last first), p keeps going
                last = s - 1
                for a in (rows_at, v, ga, inverse):
                    a[[j, last]] = a[[last, j]]
                inverse[:, [j, last]] = inverse[:, [last, j]]
                e = inverse[:last, last]
                inverse[:last, :last] -= np.outer(e, e) / inverse[last, last]
                s = last
                slack += t * dd
    return None


def _polished(g, h, active, tol):
    """(z, active, multipliers) from the active rows' equalities solved afresh, or None if they do not check."""
    if len(active) == 0:
        return np.zeros(g.shape[1]), active, np.zeros(0)
    ga = g[active]
    try:
        v = np.linalg.solve(ga @ ga.T, h[active])
    except np.linalg.LinAlgError:
        return None
    z = v @ ga
    if not (np.all(np.isfinite(z)) and np.all(v >= -NEGATIVE * v.max()) and np.all(g @ z - h >= -tol)):
        return None
    return z, active, v
