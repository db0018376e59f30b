"""Metric MDS by iterative majorisation (SMACOF), the contrast of Fig. 13 (top).

The paper maps the frames of four motions to 2-D with MDS and joins
consecutive frames: the axes mean nothing and the sequences tangle, which is
why it plots energy against time instead.  We reproduce that view.

SMACOF (de Leeuw 1977; Borg & Groenen, *Modern Multidimensional Scaling*,
ch. 8) minimises the raw stress σ(X) = Σ_{i<j} w_ij (d_ij(X) − δ_ij)² by
repeating the Guttman transform X ← V⁺ B(X) X, which never raises σ (the
majorisation guarantee a test checks).  With unit weights V⁺ B(X) X reduces
to B(X) X / n.  Everything is dense NumPy: fine for the few thousand frames a
figure holds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tonguevis.errors import TonguevisError


class MDSError(TonguevisError):
    """Dissimilarities or settings MDS cannot use."""


@dataclass
class MDSResult:
    """embedding : (n, k) coordinates (units of the dissimilarities);
    stress : final raw stress σ; stress_history : (iterations + 1,) σ from the
    initial configuration on; stress1 : Kruskal's normalised stress-1,
    sqrt(σ / Σ w δ²); n_iter : Guttman transforms done; converged : met ``tol``."""

    embedding: np.ndarray
    stress: float
    stress_history: np.ndarray
    stress1: float
    n_iter: int
    converged: bool


def pairwise_distances(x: np.ndarray) -> np.ndarray:
    """(n, n) Euclidean distances between the rows of x (n, k), exact zeros on the diagonal."""
    x = np.asarray(x, dtype=np.float64)
    sq = np.einsum("ik,ik->i", x, x)
    d2 = sq[:, None] + sq[None, :] - 2.0 * (x @ x.T)
    np.maximum(d2, 0.0, out=d2)
    np.fill_diagonal(d2, 0.0)
    return np.sqrt(d2)


def raw_stress(x: np.ndarray, delta: np.ndarray, weights: np.ndarray | None = None) -> float:
    """σ(X) = Σ_{i<j} w_ij (d_ij(X) − δ_ij)²."""
    r = pairwise_distances(x) - delta
    w = 1.0 if weights is None else weights
    return 0.5 * float(np.sum(w * r * r))


def classical_mds(delta: np.ndarray, k: int = 2) -> np.ndarray:
    """Torgerson's classical scaling: the top-k eigenvectors of the double-centred −½δ²."""
    n = len(delta)
    j = np.eye(n) - 1.0 / n
    b = -0.5 * j @ (delta ** 2) @ j
    vals, vecs = np.linalg.eigh(b)
    order = np.argsort(vals)[::-1][:k]
    return vecs[:, order] * np.sqrt(np.maximum(vals[order], 0.0))


def _check(delta: np.ndarray, weights: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    delta = np.asarray(delta, dtype=np.float64)
    if delta.ndim != 2 or delta.shape[0] != delta.shape[1] or len(delta) < 2:
        raise MDSError(f"dissimilarities must be a square matrix of at least 2 items, got shape {delta.shape}")
    if not np.all(np.isfinite(delta)) or np.any(delta < 0):
        raise MDSError("dissimilarities must be finite and non-negative")
    if not np.allclose(delta, delta.T, rtol=1e-10, atol=1e-14 * max(float(delta.max()), 1e-300)):
        raise MDSError("dissimilarities must be symmetric")
    delta = 0.5 * (delta + delta.T)
    np.fill_diagonal(delta, 0.0)
    if weights is not None:
        weights = np.asarray(weights, dtype=np.float64)
        if weights.shape != delta.shape or np.any(weights < 0) or not np.allclose(weights, weights.T):
            raise MDSError("weights must be a symmetric non-negative matrix shaped like the dissimilarities")
        weights = weights.copy()
        np.fill_diagonal(weights, 0.0)
    return delta, weights


def smacof(delta: np.ndarray, n_components: int = 2, init: str | np.ndarray = "classical",
           weights: np.ndarray | None = None, max_iter: int = 300, tol: float = 1e-7,
           random_state: int | None = 0) -> MDSResult:
    """Metric MDS of the (n, n) dissimilarities ``delta`` by SMACOF.

    init : "classical" (Torgerson), "random", or an (n, k) configuration.
    weights : optional (n, n) symmetric w_ij ≥ 0 (None: all 1).
    Stops when the relative decrease of σ falls below ``tol`` or after ``max_iter``.
    """
    delta, weights = _check(delta, weights)
    n = len(delta)
    if isinstance(init, str):
        if init == "classical":
            x = classical_mds(delta, n_components)
        elif init == "random":
            x = np.random.default_rng(random_state).normal(size=(n, n_components)) * (delta.mean() or 1.0)
        else:
            raise MDSError(f"init must be 'classical', 'random' or an array, got {init!r}")
    else:
        x = np.array(init, dtype=np.float64)
        if x.shape != (n, n_components):
            raise MDSError(f"initial configuration must be shaped ({n}, {n_components}), got {x.shape}")
    if weights is None:
        v_pinv = None
    else:
        v = -weights.copy()
        np.fill_diagonal(v, weights.sum(axis=1))
        v_pinv = np.linalg.pinv(v)
    w = 1.0 if weights is None else weights
    total = 0.5 * float(np.sum(w * delta ** 2)) or 1.0

    history = [raw_stress(x, delta, weights)]
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        d = pairwise_distances(x)
        ratio = np.divide(w * delta, d, out=np.zeros_like(d), where=d > 0)
        b = -ratio
        np.fill_diagonal(b, ratio.sum(axis=1))
        x = (b @ x) / n if v_pinv is None else v_pinv @ (b @ x)
        history.append(raw_stress(x, delta, weights))
        if history[-2] - history[-1] <= tol * max(history[-2], 1e-300):
            converged = True
            break
    history = np.asarray(history)
    return MDSResult(x, float(history[-1]), history, float(np.sqrt(history[-1] / total)), it, converged)


def frame_dissimilarities(q: np.ndarray) -> np.ndarray:
    """(F, F) distances between frames' modal displacements q (F, m).

    With mass-normalised modes ‖q_i − q_j‖ is the mass-weighted norm
    sqrt(Δuᵀ M Δu) of the linear displacement difference (m·kg^½): a shape
    distance that needs no reconstruction of the mesh.
    """
    return pairwise_distances(np.asarray(q, dtype=np.float64))
