"""Geometry of a tet mesh's boundary: normals, dorsal/inferior nodes, vertical rays.

All inputs and outputs in metres, our frame (x anterior, y left, z up).
"""

from __future__ import annotations

import os

import numpy as np

from tonguevis.mesh.tetmesh import TetMesh

#: A boundary node is upward-facing when the z of its area-weighted normal exceeds this.
UPWARD_NORMAL_Z = 0.3


def boundary_vertex_normals(mesh: TetMesh) -> tuple[np.ndarray, np.ndarray]:
    """Boundary node ids (b,) and their unit area-weighted outward normals (b, 3)."""
    faces = mesh.boundary_faces()
    p = mesh.points
    face_normals = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])  # 2 x area
    normals = np.zeros_like(p)
    for corner in range(3):
        np.add.at(normals, faces[:, corner], face_normals)
    nodes = np.unique(faces)
    n = normals[nodes]
    return nodes, n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def surface_heights(mesh: TetMesh, xy: np.ndarray, faces: np.ndarray | None = None) -> np.ndarray:
    """(q, 2) heights: lowest and highest z where the vertical line through each (q, 2)
    ``xy`` crosses the boundary; NaN where it misses the mesh."""
    faces = mesh.boundary_faces() if faces is None else faces
    tri = mesh.points[faces]                                    # (f, 3, 3)
    a, b, c = tri[:, 0, :2], tri[:, 1, :2], tri[:, 2, :2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    valid = np.abs(det) > 1e-18                                 # vertical faces never cross a vertical line
    a, b, c, tri, det = a[valid], b[valid], c[valid], tri[valid], det[valid]
    lo, hi = tri[:, :, :2].min(axis=1), tri[:, :, :2].max(axis=1)
    xy = np.asarray(xy, dtype=np.float64)
    order = np.lexsort((xy[:, 1], xy[:, 0]))                   # chunks of nearby queries ...
    out = np.full((xy.shape[0], 2), np.nan)
    for start in range(0, xy.shape[0], 128):                   # chunks bound memory, not a hot path
        rows = order[start:start + 128]
        q = xy[rows]
        # ... only meet the faces whose bounding box overlaps the chunk's
        near = np.nonzero(np.all(lo <= q.max(axis=0) + 1e-12, axis=1) & np.all(hi >= q.min(axis=0) - 1e-12, axis=1))[0]
        if near.size == 0:
            continue
        fa, fb, fc, ft, fd = a[near], b[near], c[near], tri[near], det[near]
        q = q[:, None, :]
        l1 = ((fb[:, 0] - q[..., 0]) * (fc[:, 1] - q[..., 1]) - (fc[:, 0] - q[..., 0]) * (fb[:, 1] - q[..., 1])) / fd
        l2 = ((fc[:, 0] - q[..., 0]) * (fa[:, 1] - q[..., 1]) - (fa[:, 0] - q[..., 0]) * (fc[:, 1] - q[..., 1])) / fd
        l3 = 1.0 - l1 - l2
        hit = (l1 >= -1e-12) & (l2 >= -1e-12) & (l3 >= -1e-12)
        z = l1 * ft[:, 0, 2] + l2 * ft[:, 1, 2] + l3 * ft[:, 2, 2]
        out[rows, 0] = np.where(hit, z, np.inf).min(axis=1)
        out[rows, 1] = np.where(hit, z, -np.inf).max(axis=1)
    out[~np.isfinite(out)] = np.nan
    return out


def _exposed_nodes(mesh: TetMesh, upward: bool) -> np.ndarray:
    """Boundary nodes facing up (down) with nothing of the mesh above (below) them."""
    nodes, normals = boundary_vertex_normals(mesh)
    sign = 1.0 if upward else -1.0
    candidates = nodes[sign * normals[:, 2] > UPWARD_NORMAL_Z]
    heights = surface_heights(mesh, mesh.points[candidates, :2])
    extent = float(np.ptp(mesh.points[:, 2]))
    tolerance = 0.02 * extent                                   # a node is on the envelope it tops
    z = mesh.points[candidates, 2]
    if upward:
        exposed = z >= heights[:, 1] - tolerance
    else:
        exposed = z <= heights[:, 0] + tolerance
    return np.sort(candidates[exposed | np.isnan(heights[:, 0])])


def dorsal_surface_nodes(mesh: TetMesh) -> np.ndarray:
    """(k,) ids of the upward-facing boundary nodes with no part of the mesh above them:
    the surface EMA sensors can be glued to."""
    return _exposed_nodes(mesh, upward=True)


def inferior_surface_nodes(mesh: TetMesh) -> np.ndarray:
    """(k,) ids of the downward-facing boundary nodes with no part of the mesh below them."""
    return _exposed_nodes(mesh, upward=False)


def read_surface(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a context surface (OBJ, STL, PLY, ...) -> points (n, 3) and triangles (f, 3).

    Coordinates are taken as metres, converted from millimetres (with a logged
    warning) when the extent exceeds 1.  Polygons are fan-triangulated.
    """
    from tonguevis._logging import logger

    import meshio

    from tonguevis.errors import MeshError

    if not os.path.exists(path):
        raise MeshError("no such surface file", path)
    from tonguevis.mesh.meshio_read import quiet_meshio_read

    try:
        surface = quiet_meshio_read(path)
    except meshio.ReadError as exc:
        raise MeshError(f"cannot read as a surface ({exc}); supported: OBJ, STL, PLY, VTK ...", path) from exc
    except (ValueError, KeyError, IndexError, EOFError, TypeError, AttributeError) as exc:
        raise MeshError(f"malformed surface file ({type(exc).__name__}: {exc})", path) from exc
    points = np.asarray(surface.points, dtype=np.float64)[:, :3]
    triangles = []
    for block in surface.cells:
        data = np.asarray(block.data, dtype=np.int64)
        if block.type == "triangle":
            triangles.append(data)
        elif block.type in ("quad", "polygon") or (data.ndim == 2 and data.shape[1] > 3 and "tri" not in block.type):
            for k in range(1, data.shape[1] - 1):
                triangles.append(data[:, [0, k, k + 1]])
    if not triangles or points.shape[0] == 0:
        raise MeshError(f"no triangles in the file (cell types {[c.type for c in surface.cells]})", path)
    triangles = np.concatenate(triangles)
    if triangles.min() < 0 or triangles.max() >= points.shape[0]:
        raise MeshError("triangles refer to vertices that do not exist", path)
    if not np.all(np.isfinite(points)):
        raise MeshError("non-finite vertex coordinates", path)
    if np.max(np.ptp(points, axis=0)) > 1.0:
        logger.warning("%s: extent > 1 m; reading the surface as millimetres", path)
        points = points * 1e-3
    return points, triangles
