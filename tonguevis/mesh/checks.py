"""Checks that a tetrahedral mesh is usable for FEM, with errors that name the culprits.

- node indices must exist;
- inverted tets (negative volume) are reoriented with a logged warning;
- degenerate tets (|volume| below ``DEGENERATE_RELATIVE_VOLUME`` times the mean
  |volume|, or a repeated node) are an error;
- dangling nodes (in no tet) are an error: they would carry no mass nor stiffness;
- the boundary must be a closed 2-manifold: every interior face shared by exactly
  two tets, every boundary edge by exactly two boundary faces, and the boundary
  faces around every boundary node forming a single fan.
"""

from __future__ import annotations

import os

import numpy as np

from tonguevis.errors import MeshError
from tonguevis.mesh.tetmesh import TET_FACES, face_keys, signed_tet_volumes

from tonguevis._logging import logger

#: A tet whose |volume| is below this fraction of the mean |volume| is degenerate.
DEGENERATE_RELATIVE_VOLUME = 1e-6

_MAX_LISTED = 10


def _ids(values: np.ndarray) -> str:
    """Short text listing of ids: the first few and how many in all."""
    values = np.asarray(values).ravel()
    shown = ", ".join(str(int(v)) for v in values[:_MAX_LISTED])
    more = f" ... ({values.size} in all)" if values.size > _MAX_LISTED else ""
    return shown + more


def checked_tets(points: np.ndarray, tets: np.ndarray, path: str | os.PathLike | None = None,
                 id_offset: int = 0) -> np.ndarray:
    """Validate (n, 3) ``points`` and (k, 4) ``tets``; return the tets, reoriented.

    ``id_offset`` is added to the element and node ids quoted in messages, so a
    1-based file's own numbering is reported.  Raises :class:`MeshError`.
    """
    points = np.asarray(points, dtype=np.float64)
    tets = np.array(tets, dtype=np.int64, copy=True)
    n = points.shape[0]
    if points.ndim != 2 or points.shape[1] != 3 or n == 0:
        raise MeshError(f"expected (n, 3) node coordinates, found shape {points.shape}", path)
    if tets.ndim != 2 or tets.shape[1] != 4 or tets.shape[0] == 0:
        raise MeshError(f"expected (k, 4) linear tetrahedra, found shape {tets.shape}", path)
    if not np.all(np.isfinite(points)):
        bad = np.nonzero(~np.all(np.isfinite(points), axis=1))[0]
        raise MeshError(f"non-finite coordinates at nodes {_ids(bad + id_offset)}", path)
    out_of_range = np.nonzero(np.any((tets < 0) | (tets >= n), axis=1))[0]
    if out_of_range.size:
        raise MeshError(
            f"tets {_ids(out_of_range + id_offset)} refer to nodes that do not exist "
            f"(the mesh has {n} nodes)", path)

    volumes = signed_tet_volumes(points, tets)
    mean_abs = float(np.mean(np.abs(volumes)))
    repeated = np.any(np.diff(np.sort(tets, axis=1), axis=1) == 0, axis=1)
    degenerate = np.nonzero(repeated | (np.abs(volumes) <= DEGENERATE_RELATIVE_VOLUME * mean_abs))[0]
    if degenerate.size:
        raise MeshError(
            f"degenerate tets (zero volume or a repeated node): elements {_ids(degenerate + id_offset)}",
            path)
    inverted = np.nonzero(volumes < 0)[0]
    if inverted.size:
        logger.warning("%s: reoriented %d inverted tets (elements %s)", path or "mesh",
                    inverted.size, _ids(inverted + id_offset))
        tets[inverted[:, None], [2, 3]] = tets[inverted[:, None], [3, 2]]

    used = np.zeros(n, dtype=bool)
    used[tets.ravel()] = True
    if not used.all():
        raise MeshError(f"dangling nodes in no tet: nodes {_ids(np.nonzero(~used)[0] + id_offset)}", path)

    _check_manifold(tets, path, id_offset)
    return tets


def _check_manifold(tets: np.ndarray, path, id_offset: int) -> None:
    """Raise MeshError unless the boundary of positive ``tets`` is a closed 2-manifold."""
    import scipy.sparse as sp  # lazy: keeps `import tonguevis` light
    from scipy.sparse.csgraph import connected_components

    faces = tets[:, TET_FACES].reshape(-1, 3)
    _, inverse, counts = np.unique(face_keys(faces), return_inverse=True, return_counts=True)
    face_count = counts[inverse.ravel()]
    crowded = np.nonzero(face_count > 2)[0] // 4
    if crowded.size:
        raise MeshError(
            f"non-manifold: a face is shared by more than two tets (elements {_ids(np.unique(crowded) + id_offset)})",
            path)
    boundary = faces[face_count == 1]
    owner = np.nonzero(face_count == 1)[0] // 4

    # Every boundary edge must border exactly two boundary faces.
    edges = np.sort(boundary[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    codes = (edges[:, 0] << 32) | edges[:, 1]                   # one int64 per edge: a 1-D unique
    _, first, edge_inverse, edge_counts = np.unique(codes, return_index=True, return_inverse=True,
                                                    return_counts=True)
    edge_keys = edges[first]
    edge_inverse = edge_inverse.ravel()
    bad_edges = np.nonzero(edge_counts != 2)[0]
    if bad_edges.size:
        elements = np.unique(owner[np.isin(edge_inverse, bad_edges).reshape(-1, 3).any(axis=1)])
        raise MeshError(
            f"non-manifold boundary: {bad_edges.size} edges do not border exactly two boundary faces "
            f"(nodes {_ids(np.unique(edge_keys[bad_edges]) + id_offset)}; elements {_ids(elements + id_offset)})",
            path)

    # Every boundary node's faces must form one fan.  Graph on (face, corner)
    # incidences: the two faces across a boundary edge are joined at both of its
    # end nodes; a node whose incidences fall in two components is pinched.
    n_faces = boundary.shape[0]
    incidence = np.arange(3 * n_faces).reshape(n_faces, 3)
    edge_corners = np.array([[0, 1], [1, 2], [2, 0]])
    inc_a = incidence[:, edge_corners].reshape(-1, 2)          # per (face, edge): incidences of its ends
    order = np.argsort(edge_inverse, kind="stable")             # pairs the two faces of each edge
    first, second = order[0::2], order[1::2]
    node_of_inc = boundary.ravel()
    ends_first, ends_second = inc_a[first], inc_a[second]
    # Match end nodes: the second face lists the edge's nodes in opposite order.
    same = node_of_inc[ends_first[:, 0]] == node_of_inc[ends_second[:, 0]]
    partner0 = np.where(same, ends_second[:, 0], ends_second[:, 1])
    partner1 = np.where(same, ends_second[:, 1], ends_second[:, 0])
    rows = np.concatenate([ends_first[:, 0], ends_first[:, 1]])
    cols = np.concatenate([partner0, partner1])
    graph = sp.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(3 * n_faces, 3 * n_faces))
    _, label = connected_components(graph, directed=False)
    pairs = np.unique(np.column_stack([node_of_inc, label]), axis=0)
    nodes, fans = np.unique(pairs[:, 0], return_counts=True)
    pinched = nodes[fans > 1]
    if pinched.size:
        raise MeshError(
            f"non-manifold boundary: the boundary is pinched at nodes {_ids(pinched + id_offset)} "
            f"(their boundary faces do not form a single fan)", path)
