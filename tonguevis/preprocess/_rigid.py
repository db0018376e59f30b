"""Batched least-squares rigid and similarity fits (Kabsch / Umeyama).

For point sets A (source) and B (target) with matching rows, the proper
rotation R minimising sum |R a_i + t - b_i|^2 comes from the SVD of the
cross-covariance H = sum (a_i - a_bar)(b_i - b_bar)^T = U S V^T:
R = V D U^T with D = diag(1, 1, sign det(V U^T)) forbidding reflections.
Umeyama's scale is trace(S D) / sum |a_i - a_bar|^2.
"""

from __future__ import annotations

import numpy as np


def fit_rotations(source: np.ndarray, target: np.ndarray):
    """Least-squares similarity of many point sets at once.

    source, target : (..., P, 3) float; every row valid (the caller masks).
    Returns (rotation (..., 3, 3) proper, scale (...,) Umeyama's optimal
    uniform scale, source centroid (..., 3), target centroid (..., 3),
    singular values (..., 3) of the cross-covariance).
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    src_c = source.mean(axis=-2)
    tgt_c = target.mean(axis=-2)
    a = source - src_c[..., None, :]
    b = target - tgt_c[..., None, :]
    cov = np.einsum("...pi,...pj->...ij", a, b)  # (..., 3, 3) = sum a b^T
    u, s, vt = np.linalg.svd(cov)
    v = np.swapaxes(vt, -1, -2)
    ut = np.swapaxes(u, -1, -2)
    sign = np.sign(np.linalg.det(v @ ut))
    sign = np.where(sign == 0, 1.0, sign)
    d = np.ones(s.shape)
    d[..., -1] = sign
    rotation = (v * d[..., None, :]) @ ut
    spread = np.einsum("...pi,...pi->...", a, a)
    scale = np.einsum("...i,...i->...", s, d) / np.where(spread > 0, spread, 1.0)
    return rotation, scale, src_c, tgt_c, s
