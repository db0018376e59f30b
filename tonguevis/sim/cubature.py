"""Optimised cubature for the domains' reduced StVK force (An, Kim and James 2008; seed 001 §6).

The reduced force Bᵀf(Bz) = Σ_e g_e(z) sums every tet's contribution g_e(z) = −V_e D_eᵀ P_e(F_e)
(D_e = ∂F_e/∂z).  A cubature keeps a few tets E and non-negative weights c_e so that
Σ_{e∈E} c_e g_e(z)/V_e·V_e ≈ Σ_e g_e(z) on training poses: greedy selection of the tet whose
contribution best matches the remaining residual, then non-negative least squares on the tets
kept (scipy.optimize.nnls), until the relative residual on the training poses falls below
``tolerance`` or ``max_tets`` are kept.  The training poses here are the domain model's own
*linear* static shapes for random sensor displacements of 5-20 mm (cheap and of the shapes a
simulation makes); :meth:`Cubature.relative_error` states the error on any other poses.

The tangent of the cubature force is the same sum of the kept tets' exact tangents
(Σ c_e/V_e B_eᵀ K_e B_e), so Newton stays exact for the approximated force.
"""

from __future__ import annotations

from tonguevis._logging import logger

import numpy as np

from tonguevis.sim.stvk import StVK

#: Tets added per greedy round.
PER_ROUND = 8


def training_poses(dm, count: int = 24, seed: int = 0, low: float = 5e-3, high: float = 20e-3) -> np.ndarray:
    """(count, r) linear static shapes of ``dm`` (a :class:`~tonguevis.sim.domains.DomainModel`) for random
    displacements of its sensor nodes, each sensor moving ``low``-``high`` m in a random direction."""
    rng = np.random.default_rng(seed)
    rows = dm.rows(dm.sensor_nodes).reshape(-1, dm.n_dofs)
    lam = dm.eigenvalues
    gram = (rows / lam) @ rows.T
    out = np.empty((count, dm.n_dofs))
    for p in range(count):
        d = rng.standard_normal((len(dm.sensor_nodes), 3))
        d *= rng.uniform(low, high, len(d))[:, None] / np.linalg.norm(d, axis=1, keepdims=True)
        out[p] = (rows / lam).T @ np.linalg.solve(gram, d.ravel())
    return out


class Cubature:
    """Kept tets and weights approximating ``dm``'s reduced StVK force.

    tets : (T,) kept tet ids; weights : (T,) m³ (each tet's volume replaced by its weight);
    training_error : relative residual |Σ c g − f| / |f| on the training poses.
    """

    def __init__(self, dm, poses: np.ndarray | None = None, tolerance: float = 0.01, max_tets: int = 400,
                 _given: tuple | None = None):
        from scipy.optimize import nnls

        if _given is not None:  # from_weights: the selection is known
            self._setup(dm, *_given)
            return

        self.dm = dm
        poses = training_poses(dm) if poses is None else np.atleast_2d(poses)
        solid = dm.solid
        df = dm._df  # (k, 9, r)
        columns = []
        for z in poses:  # per pose, per tet: the reduced force per unit volume, (k, r)
            _, _, p = solid.stresses(dm._deformation(z))
            columns.append(-np.einsum("kx,kxr->kr", p.reshape(-1, 9), df))
        a = np.concatenate(columns, axis=1).T  # (P·r, k): column e = g_e / V_e over all poses
        b = a @ solid.volumes
        norms = np.linalg.norm(a, axis=0)
        norms[norms == 0] = 1.0
        chosen: list[int] = []
        residual = b.copy()
        weights = np.zeros(0)
        while len(chosen) < max_tets:
            score = (a.T @ residual) / norms
            score[chosen] = -np.inf
            # several tets per round (the best matches of the residual): ten times fewer NNLS solves
            # than one at a time (71 s on the shipped tongue), for a few more tets
            chosen.extend(int(e) for e in np.argsort(score)[::-1][:PER_ROUND] if np.isfinite(score[e]))
            weights, _ = nnls(a[:, chosen], b, maxiter=50 * len(chosen))
            residual = b - a[:, chosen] @ weights
            if np.linalg.norm(residual) <= tolerance * np.linalg.norm(b):
                break
        keep = weights > 0
        self._setup(dm, np.array(chosen)[keep], weights[keep], float(np.linalg.norm(residual) / np.linalg.norm(b)))

    @classmethod
    def from_weights(cls, dm, tets: np.ndarray, weights: np.ndarray, training_error: float) -> "Cubature":
        """The cubature of ``dm`` with these kept ``tets`` and ``weights`` (e.g. from the cache)."""
        return cls(dm, _given=(np.asarray(tets, dtype=np.int64), np.asarray(weights, dtype=np.float64),
                               float(training_error)))

    def _setup(self, dm, tets, weights, training_error) -> None:
        self.dm, self.tets, self.weights, self.training_error = dm, tets, weights, training_error
        solid, df = dm.solid, dm._df
        self._solid = StVK(solid.points, solid.tets[self.tets], solid.young, solid.poisson, solid.density)
        self._df2 = np.ascontiguousarray(df[self.tets].reshape(-1, df.shape[-1]))  # (9T, r)
        tet_dofs = (3 * solid.tets[self.tets][:, :, None] + np.arange(3)).reshape(-1, 12)
        self._b_tet = dm.basis[tet_dofs]  # (T, 12, r)

    def force(self, z: np.ndarray) -> np.ndarray:
        """(r,) the cubature's reduced internal force, N."""
        f_grad = (self._df2 @ z).reshape(-1, 3, 3) + np.eye(3)
        _, _, p = self._solid.stresses(f_grad)
        return -(self.weights[:, None] * p.reshape(-1, 9)).ravel() @ self._df2

    def tangent(self, z: np.ndarray) -> np.ndarray:
        """(r, r) its tangent: Σ c_e/V_e B_eᵀ K_e(z) B_e, N/m."""
        u = self.dm.displacement(z)
        ke = self._solid.element_tangents(u) * (self.weights / self._solid.volumes)[:, None, None]
        kb = np.matmul(ke, self._b_tet).reshape(-1, self._b_tet.shape[-1])  # (12T, r)
        return self._b_tet.reshape(-1, self._b_tet.shape[-1]).T @ kb

    def relative_error(self, poses: np.ndarray) -> float:
        """Largest |f_cubature − f| / |f| over ``poses`` (P, r) (the full-mesh force as the reference)."""
        return float(max(np.linalg.norm(self.force(z) - self.dm.full_force(z)) / np.linalg.norm(self.dm.full_force(z))
                         for z in np.atleast_2d(poses)))


CACHE_VERSION = 1


def cubature_for(dm, tolerance: float = 0.01, max_tets: int = 400, cache: bool = True) -> Cubature:
    """The cubature of ``dm`` from the disk cache (tets and weights, .npz without pickle) or built (30 s on the
    shipped tongue) and cached; keyed by the domains, the subspace size and the settings."""
    import hashlib
    import zipfile

    from tonguevis._files import atomic_write

    key = hashlib.sha256(f"cubature v{CACHE_VERSION}|{dm.domains.key}|{dm.n_dofs}|{tolerance}|{max_tets}|"
                         f"{PER_ROUND}".encode()).hexdigest()[:32]
    path = None
    if cache:
        from tonguevis.paths import cache_dir

        path = cache_dir() / f"cubature-{key}.npz"
        if path.exists():
            try:
                with np.load(path, allow_pickle=False) as data:
                    if str(data["key"]) == key:
                        return Cubature.from_weights(dm, np.array(data["tets"]), np.array(data["weights"]),
                                                     float(data["training_error"]))
            except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
                logger.warning("ignoring unreadable cubature cache %s (%s)", path, exc)
    cub = Cubature(dm, tolerance=tolerance, max_tets=max_tets)
    if path is not None:
        def write(tmp):
            with open(tmp, "wb") as fh:
                np.savez(fh, tets=cub.tets, weights=cub.weights, training_error=np.array(cub.training_error),
                         key=np.array(key))
        try:
            atomic_write(path, write)
        except OSError as exc:
            logger.warning("could not cache the cubature at %s: %s", path, exc)
    return cub
