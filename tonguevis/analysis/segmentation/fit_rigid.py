"""Rigid modes (eqs. 7-9): the least-squares rigid fit of a partition.

The six rigid modes of a partition span the infinitesimal rigid motions
``ũ(x) = a + θ × (x − c)``; eq. (9) projects the target onto them.  The
projection needs only sums over the partition's tets (volume, first and second
moments of position, moments of the target), so every tet carries its own
sums and a partition's fit is a sum and a 3 × 3 solve: adding a one-ring to a
partition costs as much as the ring, not the partition.
"""

from __future__ import annotations

import numpy as np

from tonguevis.analysis.segmentation.fitter import LocalFitter


def rigid_coefficients(m0, m1, m2, s, t):
    """Solve the weighted rigid projection from moments.

    m0 : scalar total weight (m³); m1 : (3,) Σ w x; m2 : (3, 3) Σ w x xᵀ;
    s : (r, 3) Σ w y_j; t : (r, 3) Σ w x × y_j.
    Returns ``a`` (r, 3), ``theta`` (r, 3), centre ``c`` (3,) and the squared
    norm of the projection Σ_j ⟨y_j, P y_j⟩ (so error = Σ w|y|² − that).
    """
    c = m1 / m0
    m2c = m2 - m0 * np.outer(c, c)
    tc = t - np.cross(c, s)
    inertia = np.trace(m2c) * np.eye(3) - m2c
    a = s / m0
    theta = np.linalg.solve(inertia, tc.T).T
    captured = float(np.sum(s * s) / m0 + np.sum(theta * tc))
    return a, theta, c, captured


class RigidFitter(LocalFitter):
    """Least-squares rigid fit of tet sets (eq. 9) in the volume-lumped norm."""

    mode = "rigid"

    def _prepare(self) -> None:
        x = self.points - self.points.mean(axis=0)  # centred: keeps m2 - m0 c cᵀ accurate
        self._x = x
        quarter = self.tet_volumes / 4.0
        corners = x[self.tets]  # (k, 4, 3)
        m0 = self.tet_volumes
        m1 = quarter[:, None] * corners.sum(axis=1)
        m2 = quarter[:, None, None] * np.einsum("kai,kaj->kij", corners, corners)
        y = np.transpose(self.columns, (1, 0, 2))[self.tets]  # (k, 4, r, 3)
        s = quarter[:, None, None] * y.sum(axis=1)  # (k, r, 3)
        t = quarter[:, None, None] * np.cross(corners[:, :, None, :], y).sum(axis=1)
        q = quarter * np.einsum("karj,karj->k", y, y)
        self._r = y.shape[2]
        # one row of additive moments per tet: a set's sums are one matrix-vector product
        self._moments = np.concatenate([m0[:, None], m1, m2.reshape(-1, 9), s.reshape(len(s), -1),
                                        t.reshape(len(t), -1), q[:, None]], axis=1)

    def _compute_error(self, members: np.ndarray) -> float:
        mask = np.zeros(len(self.tets))
        mask[members] = 1.0
        sums = mask @ self._moments
        r = self._r
        m0, m1, m2 = sums[0], sums[1:4], sums[4:13].reshape(3, 3)
        s = sums[13:13 + 3 * r].reshape(r, 3)
        t = sums[13 + 3 * r:13 + 6 * r].reshape(r, 3)
        _, _, _, captured = rigid_coefficients(m0, m1, m2, s, t)
        return max(float(sums[-1] - captured), 0.0)

    def approximate(self, members: np.ndarray, displacements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rigid fit of each frame: nodes (p,) and (F, p, 3) displacements in m."""
        nodes, weights = self.node_weights(members)
        x = self._x[nodes]
        y = np.transpose(displacements[:, nodes, :], (1, 0, 2))  # (p, F, 3)
        m0 = weights.sum()
        m1 = weights @ x
        m2 = np.einsum("p,pi,pj->ij", weights, x, x)
        s = np.einsum("p,pfi->fi", weights, y)
        t = np.einsum("p,pfi->fi", weights, np.cross(x[:, None, :], y))
        a, theta, c, _ = rigid_coefficients(m0, m1, m2, s, t)
        fit = a[:, None, :] + np.cross(theta[:, None, :], (x - c)[None, :, :])
        return nodes, fit
