"""Closed or open, wound which way, and the vertex normals of a triangle surface (NumPy/SciPy only).

The 3D views light every surface at its vertices and skip the faces nobody can
see (:mod:`tonguevis.render.scene`): for that they need smooth vertex normals that
point out of a closed surface whichever way its triangles are wound, and which
side of it is the hidden inside.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


class VertexNormals:
    """Area-weighted vertex normals of a triangle surface, vectorised (the surface
    deforms every frame, so shading normals are recomputed in place)."""

    def __init__(self, faces: np.ndarray, n_points: int):
        self.faces = np.asarray(faces, dtype=np.int64)
        f = len(self.faces)
        rows = self.faces.ravel()
        cols = np.repeat(np.arange(f), 3)
        self.incidence = sp.csr_matrix((np.ones(3 * f), (rows, cols)), shape=(n_points, f))

    def __call__(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        a, b, c = (p[self.faces[:, k]] for k in range(3))
        face_normals = np.cross(b - a, c - a)  # length = 2 × area: area weighting for free
        normals = self.incidence @ face_normals
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        length[length == 0] = 1.0
        return (normals / length).astype(np.float32)


def is_closed(faces: np.ndarray) -> bool:
    """Whether a triangle surface (f, 3) is closed: every edge is shared by exactly two triangles."""
    faces = np.asarray(faces, dtype=np.int64)
    if not len(faces):
        return False
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool(np.all(counts == 2))


def wound_inwards(points: np.ndarray, faces: np.ndarray) -> bool:
    """Whether a closed triangle surface's triangles are wound clockwise seen from outside
    (its signed volume is negative): VTK's front faces are then its inside."""
    p = np.asarray(points, dtype=np.float64)
    a, b, c = (p[np.asarray(faces, dtype=np.int64)[:, k]] for k in range(3))
    return bool(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() < 0.0)  # 6 × signed volume


def outward_normals(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(n, 3) vertex normals of a triangle surface, pointing out of it if it is closed
    (a surface wound inwards is turned: the lighting of a closed shell is one-sided)."""
    faces = np.asarray(faces, dtype=np.int64)
    if is_closed(faces) and wound_inwards(points, faces):
        faces = faces[:, ::-1]
    return VertexNormals(faces, len(points))(np.asarray(points, dtype=np.float64))


def hidden_side(points: np.ndarray, faces: np.ndarray) -> str | None:
    """Which faces of a surface an opaque or shell drawing can skip: its inside ("back", or
    "front" for a closed surface wound inwards); None for an open surface, seen from both sides."""
    if not is_closed(faces):
        return None
    return "front" if wound_inwards(points, faces) else "back"
