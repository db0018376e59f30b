"""Structured test meshes with their nodes moved at random, so tet volumes differ.

On a structured box every tet has the same volume, so any volume weighting
(nodal averages, lumped masses) cannot matter there and a test on it cannot
see the weighting go missing.  Jittering the nodes breaks that symmetry.
"""

from __future__ import annotations

import numpy as np

from tonguevis.mesh.tetmesh import signed_tet_volumes


def jittered(points: np.ndarray, tets: np.ndarray, fraction: float = 0.2, seed: int = 0) -> np.ndarray:
    """(n, 3) copy of ``points`` with every node moved by up to ``fraction`` of the shortest edge per axis.

    The tets keep their (positive) orientation; raises if one would flip.
    """
    edges = points[tets[:, [0, 0, 0, 1, 1, 2]]] - points[tets[:, [1, 2, 3, 2, 3, 3]]]
    shortest = float(np.linalg.norm(edges, axis=2).min())
    rng = np.random.default_rng(seed)
    moved = points + rng.uniform(-fraction, fraction, size=points.shape) * shortest
    before, after = signed_tet_volumes(points, tets), signed_tet_volumes(moved, tets)
    if np.any(np.sign(before) != np.sign(after)) or np.any(after == 0):
        raise ValueError(f"jitter of {fraction} edge lengths flips a tet; use a smaller fraction")
    return moved


def volume_spread(points: np.ndarray, tets: np.ndarray) -> float:
    """Largest over smallest |tet volume|."""
    v = np.abs(signed_tet_volumes(points, tets))
    return float(v.max() / v.min())
