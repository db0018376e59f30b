"""Structured tetrahedral box meshes, for verification problems (beams, bars)."""

from __future__ import annotations

import numpy as np

from tonguevis.mesh.tetmesh import TetMesh, signed_tet_volumes

# Kuhn subdivision of the unit cube into six tets sharing the diagonal 0-7;
# corners numbered by bits (x, y, z) -> x + 2y + 4z.  Neighbouring cubes match face to face.
_KUHN = np.array([[0, 1, 3, 7], [0, 3, 2, 7], [0, 2, 6, 7], [0, 6, 4, 7], [0, 4, 5, 7], [0, 5, 1, 7]])


def box_mesh(nx: int, ny: int, nz: int, size=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0)) -> TetMesh:
    """A box of nx × ny × nz cubes, six positive tets each.

    size : (3,) edge lengths in metres; origin : (3,) lowest corner.
    Returns a :class:`TetMesh` with (nx+1)(ny+1)(nz+1) nodes and 6 nx ny nz tets.
    """
    counts = np.array([nx, ny, nz])
    if np.any(counts < 1):
        raise ValueError(f"box_mesh needs at least one cell per axis, got {tuple(counts)}")
    axes = [np.linspace(o, o + s, n + 1) for o, s, n in zip(origin, size, counts)]
    gx, gy, gz = np.meshgrid(*axes, indexing="ij")
    points = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    index = np.arange(len(points)).reshape(nx + 1, ny + 1, nz + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))
    # Mirror the pattern in every other cell along each axis: neighbours still
    # share face diagonals, and the mesh has no preferred diagonal direction,
    # which removes most of the bending anisotropy of a plain Kuhn grid.
    fi, fj, fk = i % 2, j % 2, k % 2
    corners = np.stack(
        [index[i + ((c & 1) ^ fi), j + (((c >> 1) & 1) ^ fj), k + (((c >> 2) & 1) ^ fk)] for c in range(8)],
        axis=1,
    )  # (cells, 8)
    tets = corners[:, _KUHN].reshape(-1, 4)
    negative = signed_tet_volumes(points, tets) < 0
    tets[negative] = tets[negative][:, [0, 2, 1, 3]]
    return TetMesh(points, tets, metadata={"source": f"box_mesh({nx}, {ny}, {nz}, size={tuple(size)})"})
