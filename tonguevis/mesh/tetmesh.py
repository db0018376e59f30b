"""The tetrahedral mesh container :class:`TetMesh`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class TetMesh:
    """A linear tetrahedral mesh.

    points : (n, 3) float64 node positions in metres (tonguevis frame:
        x anterior, y left, z up, when the mesh is a tongue).
    tets : (k, 4) int64 node indices, every tet positively oriented
        (det[p1-p0, p2-p0, p3-p0] > 0).
    metadata : free-form (source file, unit conversions applied, ...).
    """

    points: np.ndarray
    tets: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.points = np.ascontiguousarray(self.points, dtype=np.float64)
        self.tets = np.ascontiguousarray(self.tets, dtype=np.int64)

    @property
    def n_nodes(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_tets(self) -> int:
        return int(self.tets.shape[0])

    def tet_volumes(self, points: np.ndarray | None = None) -> np.ndarray:
        """(k,) signed volumes in m³ (of ``points`` if given, e.g. a deformed state)."""
        p = self.points if points is None else points
        return signed_tet_volumes(p, self.tets)

    @property
    def volume(self) -> float:
        """Total rest volume in m³."""
        return float(self.tet_volumes().sum())

    def boundary_faces(self) -> np.ndarray:
        """(f, 3) node triples of the faces that belong to exactly one tet, outward."""
        return boundary_faces(self.tets)


# Faces of tet (0,1,2,3), each ordered so its normal points out of a positive tet.
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)


def signed_tet_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """(..., k) signed tet volumes; ``points`` may carry leading frame axes (..., n, 3)."""
    p = np.asarray(points)
    a = p[..., tets[:, 1], :] - p[..., tets[:, 0], :]
    b = p[..., tets[:, 2], :] - p[..., tets[:, 0], :]
    c = p[..., tets[:, 3], :] - p[..., tets[:, 0], :]
    return np.einsum("...i,...i->...", a, np.cross(b, c)) / 6.0


def boundary_faces(tets: np.ndarray) -> np.ndarray:
    """(f, 3) faces used by exactly one tet, oriented outward for positive tets."""
    faces = tets[:, TET_FACES].reshape(-1, 3)
    _, inverse, counts = np.unique(face_keys(faces), return_inverse=True, return_counts=True)
    return faces[counts[inverse.ravel()] == 1]


def face_keys(faces: np.ndarray) -> np.ndarray:
    """(f,) int64 key per (f, 3) node triple, equal for the same nodes in any order.

    One integer per face makes ``np.unique`` a 1-D sort, many times faster than
    ``np.unique(..., axis=0)`` on rows.  Exact for up to 2,097,151 nodes.
    """
    key = np.sort(np.asarray(faces, dtype=np.int64), axis=1)
    if key.size and key.max() >= 1 << 21:
        raise ValueError("face_keys supports node indices below 2**21")
    return (key[:, 0] << 42) | (key[:, 1] << 21) | key[:, 2]
