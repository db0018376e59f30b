"""Constriction degree and location: where a sensor is relative to the palate, at any frame.

MVIEW's palate distance (``MDP_PALDIST``) and the constriction location of EMA studies of stops
(see the README's "Measures"), on a :class:`~tonguevis.palate.PalateSurface`:

* **degree**: the shortest 3-D distance from a point (a tongue sensor) to the palate's surface,
  signed: positive below the palate (in the mouth), negative above it (the sensor read higher
  than the palate, e.g. a palate traced in another sitting, or a soft palate the dorsum lifts);
* **location**: where the closest palate point lies along the palate's midline, measured from
  the palate's front (the most anterior point of its midsagittal profile), as arc length (m);
* **at the edge**: whether the closest point lies on the palate's boundary, i.e. the sensor is
  beyond the palate's extent (a traced palate covers the front of the roof only: at /k/ the
  dorsum is often behind it) and the distance is to its edge, not to a roof above it.

The surface is the palate's triangle mesh (:meth:`PalateSurface.triangles`: the height field's
grid cells, two triangles each); the distance is exact to that mesh (closest point on each
candidate triangle, after Ericson, *Real-Time Collision Detection*, 2005, §5.1.5), not the
height field's vertical gap times the slope's cosine that :meth:`PalateSurface.clearance` gives.
Everything is computed in the palate's own frame and scaled back (its transform is a similarity),
vectorised over all points at once (any number of frames).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

#: Points are measured in chunks of this many (memory: chunk x candidate triangles).
CHUNK = 4096
#: Region codes of the closest point on a triangle: a vertex (0-2), an edge (3: ab, 4: ac, 5: bc), inside (6).
_A, _B, _C, _AB, _AC, _BC, _INSIDE = range(7)


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The closest point on triangle (a, b, c) to p, row by row: (closest (k, 3), region (k,) int).

    p, a, b, c : (k, 3).  Region: 0-2 a vertex (a, b, c), 3-5 an edge (ab, ac, bc), 6 the inside.
    Degenerate (zero-area) triangles give a point on them, never NaN.
    """
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2

    def ratio(num, den):
        return np.clip(np.divide(num, den, out=np.zeros_like(num), where=np.abs(den) > 0), 0.0, 1.0)

    total = va + vb + vc
    v_in, w_in = ratio(vb, total), ratio(vc, total)
    out = a + ab * v_in[:, None] + ac * w_in[:, None]
    region = np.full(len(p), _INSIDE)
    # Later assignments win: the order is the reverse of Ericson's tests, so his first test decides.
    cases = [
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), _BC,
         lambda: b + (c - b) * ratio(d4 - d3, (d4 - d3) + (d5 - d6))[:, None]),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), _AC, lambda: a + ac * ratio(d2, d2 - d6)[:, None]),
        ((d6 >= 0) & (d5 <= d6), _C, lambda: c),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), _AB, lambda: a + ab * ratio(d1, d1 - d3)[:, None]),
        ((d3 >= 0) & (d4 <= d3), _B, lambda: b),
        ((d1 <= 0) & (d2 <= 0), _A, lambda: a),
    ]
    for mask, code, point in cases:
        if mask.any():
            out = np.where(mask[:, None], point(), out)
            region = np.where(mask, code, region)
    return out, region


@dataclass
class Constriction:
    """Where points are relative to a palate (one entry per point; NaN where a point is NaN).

    degree : (k,) m, the shortest distance to the palate surface, negative above it;
    location : (k,) m along the palate's midline from its front to the closest point;
    closest : (k, 3) m, the closest palate point (the query frame);
    at_edge : (k,) bool, the closest point lies on the palate's boundary (the point is beyond it).
    """

    degree: np.ndarray
    location: np.ndarray
    closest: np.ndarray
    at_edge: np.ndarray


class PalateGeometry:
    """A palate's triangles, their downward normals, its boundary and its midline, for :meth:`constriction`.

    Build it once per palate (:func:`palate_geometry`) and measure any number of points with it.
    ``surface`` : a :class:`~tonguevis.palate.PalateSurface` (metres; queries in its query frame).
    """

    def __init__(self, surface):
        from scipy.spatial import cKDTree

        self.surface = surface
        x, y, z = (np.asarray(a, dtype=np.float64) for a in (surface.x, surface.y, surface.z))
        gx, gy = np.meshgrid(x, y)
        grid = np.column_stack([gx.ravel(), gy.ravel(), z.ravel()])
        ok = np.isfinite(grid[:, 2])
        index = np.full(len(grid), -1)
        index[ok] = np.arange(ok.sum())
        ids = np.arange(z.size).reshape(z.shape)
        quads = np.stack([ids[:-1, :-1], ids[:-1, 1:], ids[1:, 1:], ids[1:, :-1]], axis=-1).reshape(-1, 4)
        tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
        tris = tris[np.all(ok[tris], axis=1)]
        #: (n, 3) vertices and (f, 3) triangles in the palate's own frame (m), as :meth:`PalateSurface.triangles`.
        self.vertices, self.faces = grid[ok], index[tris]
        if len(self.faces) == 0:
            from tonguevis.palate import PalateError

            raise PalateError("the palate has no surface to measure against (no grid cell with four heights)")
        a, b, c = (self.vertices[self.faces[:, k]] for k in range(3))
        normal = np.cross(b - a, c - a)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        #: (f, 3) unit normals pointing down, out of the palate into the mouth (own frame).
        self.normals = np.where(normal[:, 2:3] > 0, -normal, normal)
        edges = np.sort(np.concatenate([self.faces[:, [0, 1]], self.faces[:, [0, 2]], self.faces[:, [1, 2]]]), axis=1)
        unique, inverse, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
        boundary = counts[inverse.ravel()] == 1
        #: (f, 3) bool: each face's edges ab, ac, bc lie on the palate's boundary.
        self.boundary_edges = boundary.reshape(3, -1).T
        self.boundary_vertices = np.zeros(len(self.vertices), dtype=bool)
        self.boundary_vertices[unique[counts == 1].ravel()] = True
        # Every point of a triangle lies within its longest edge / sqrt(3) of one of its vertices (the
        # circumradius of an acute triangle is at most that; an obtuse one is covered by less).
        self._reach = float(np.max(np.linalg.norm(np.concatenate([b - a, c - a, c - b]), axis=1))) / np.sqrt(3.0)
        self._tree = cKDTree(self.vertices)
        faces_of = np.argsort(self.faces.ravel(), kind="stable")
        self._incident = (faces_of // 3, np.searchsorted(self.faces.ravel()[faces_of], np.arange(len(self.vertices) + 1)))

    # ------------------------------------------------------------------ the midline
    @cached_property
    def midline_y(self) -> float:
        """The midline's y in the palate's own frame (m): the fit's (mirrored about it), else the centre of the
        footprint's width (the generic palate is symmetric; a joined palate's own frame is the query frame)."""
        meta = self.surface.metadata
        if meta.get("midline_y") is not None and "joined" not in meta:
            return float(meta["midline_y"])
        ys = self.vertices[:, 1]
        return float(0.5 * (ys.min() + ys.max()))

    @cached_property
    def midline(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The palate's midsagittal profile in its own frame: (x (n,) decreasing from the front, z (n,),
        arc length (n,) from the front), m, on the grid's x where the palate has a height at the midline."""
        x = np.asarray(self.surface.x, dtype=np.float64)
        h, _ = self.surface._interp(np.column_stack([x, np.full(len(x), self.midline_y)]))
        ok = np.isfinite(h)
        if ok.sum() < 2:  # no profile on the midline (a palate of one side): the highest point of each column
            z = np.asarray(self.surface.z, dtype=np.float64)
            h = np.where(np.isfinite(z).any(axis=0), np.nanmax(np.where(np.isfinite(z), z, -np.inf), axis=0), np.nan)
            ok = np.isfinite(h)
        xs, zs = x[ok][::-1], h[ok][::-1]  # from the front (largest x) backwards
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(xs), np.diff(zs)))])
        return xs, zs, arc

    def midline_points(self) -> np.ndarray:
        """(n, 3) the midsagittal profile from the front backwards, in the query frame (m): for drawing."""
        xs, zs, _ = self.midline
        return self.surface._from_own(np.column_stack([xs, np.full(len(xs), self.midline_y), zs]))

    def location_of(self, own_points: np.ndarray) -> np.ndarray:
        """(k,) m of the query frame: arc length along the midline from the front to each own-frame point's x."""
        xs, _, arc = self.midline
        x = np.asarray(own_points, dtype=np.float64)[:, 0]
        located = np.interp(-x, -xs, arc)  # xs decrease: interpolate on -x (increasing)
        return np.where(np.isfinite(x), located * self.surface.scale, np.nan)

    # ------------------------------------------------------------------ distances
    def _candidates(self, own: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(point index, face index) pairs that can hold each point's closest point: the faces around every
        vertex within (distance to the nearest vertex + the faces' covering radius).  The closest point is no
        further than the nearest vertex, and one vertex of its face lies within the covering radius of it."""
        nearest, _ = self._tree.query(own)
        balls = self._tree.query_ball_point(own, nearest + self._reach + 1e-12)
        counts = np.fromiter((len(b) for b in balls), dtype=np.int64, count=len(balls))
        vertex = np.concatenate([np.asarray(b, dtype=np.int64) for b in balls]) if counts.sum() else np.zeros(0, int)
        point = np.repeat(np.arange(len(own)), counts)
        faces, starts = self._incident
        first, last = starts[vertex], starts[vertex + 1]
        per = last - first
        which = np.repeat(np.arange(len(vertex)), per)
        offset = np.arange(per.sum()) - np.repeat(np.cumsum(per) - per, per)
        n_faces = len(self.faces)
        keys = np.sort(point[which] * n_faces + faces[first[which] + offset])
        keys = keys[np.r_[True, keys[1:] != keys[:-1]]]  # each (point, face) once
        return keys // n_faces, keys % n_faces

    def _closest_own(self, own: np.ndarray):
        """Own-frame closest points of finite points ``own`` (k, 3): (distance, closest, face, region)."""
        point, face = self._candidates(own)
        a, b, c = (self.vertices[self.faces[face, k]] for k in range(3))
        closest, region = closest_on_triangles(own[point], a, b, c)
        distance = np.linalg.norm(own[point] - closest, axis=1)
        order = np.lexsort((distance, point))  # per point, the nearest candidate first
        first = order[np.r_[True, point[order][1:] != point[order][:-1]]]
        return distance[first], closest[first], face[first], region[first]

    def constriction(self, points: np.ndarray) -> Constriction:
        """Degree, location, closest point and edge flag of (k, 3) query-frame points (m); see the module doc."""
        surface = self.surface
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        k = len(points)
        degree, location = np.full(k, np.nan), np.full(k, np.nan)
        closest, at_edge = np.full((k, 3), np.nan), np.zeros(k, dtype=bool)
        finite = np.flatnonzero(np.isfinite(points).all(axis=1))
        for start in range(0, len(finite), CHUNK):
            rows = finite[start:start + CHUNK]
            own = surface._to_own(points[rows])
            distance, near, face, region = self._closest_own(own)
            # Below or above: over the palate's footprint its height decides; beyond it, the nearest face's side.
            height, _ = surface._interp(own[:, :2])
            side = np.where(np.isfinite(height), height - own[:, 2],
                            np.einsum("ij,ij->i", own - near, self.normals[face]))
            degree[rows] = np.where(side < 0, -distance, distance) * surface.scale
            closest[rows] = surface._from_own(near)
            location[rows] = self.location_of(near)
            at_edge[rows] = self._on_boundary(face, region)
        return Constriction(degree, location, closest, at_edge)

    def _on_boundary(self, face: np.ndarray, region: np.ndarray) -> np.ndarray:
        edge = np.zeros(len(face), dtype=bool)
        for code, column in ((_AB, 0), (_AC, 1), (_BC, 2)):
            hit = region == code
            edge[hit] = self.boundary_edges[face[hit], column]
        for code in (_A, _B, _C):
            hit = region == code
            edge[hit] = self.boundary_vertices[self.faces[face[hit], code]]
        return edge


def palate_geometry(surface) -> PalateGeometry:
    """A :class:`PalateGeometry` of ``surface`` (a PalateSurface), kept on it: built once per palate object."""
    cached = getattr(surface, "_constriction_geometry", None)
    if cached is None or cached.surface is not surface:
        cached = PalateGeometry(surface)
        try:
            surface._constriction_geometry = cached  # a plain dataclass: the attribute rides along, uncompared
        except AttributeError:  # pragma: no cover - a frozen or slotted surface: rebuilt each time
            pass
    return cached


def constriction(surface, points: np.ndarray) -> Constriction:
    """Constriction degree and location of (k, 3) points (m, the palate's query frame) against ``surface``.

    For any frame or all of them: ``constriction(palate, recording.sensors["TT"])`` measures every
    sample of TT (NaN samples stay NaN).  See the module docstring for the definitions.
    """
    return palate_geometry(surface).constriction(points)
