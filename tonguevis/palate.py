"""The speaker's palate: a smooth surface fitted to palate traces, and distances to it.

EMA sessions routinely trace the palate with a probe sensor drawn along the
midline, across, or scribbled over it.  :func:`fit_palate` turns the probe's
positions (head-corrected like the speech recordings of the same session, in
the recording's frame: x anterior, y left, z up, metres) into a
:class:`PalateSurface`: a height field z = h(x, y) on a regular grid,

* mirrored about the midline (the plane about which the traced points are
  most nearly mirror images, :func:`symmetry_midline`; the mean y of the
  tongue's lateral sensors when one side only was traced, else the points'
  median y), so a palate traced on one side only is whole;
* fitted by a smoothing thin-plate spline (SciPy's ``RBFInterpolator``), with
  points more than 3 robust standard deviations off the fit dropped and the
  fit repeated (the probe entering or leaving the mouth, a slip off the palate),
  its smoothing raised until the surface bends nowhere more tightly than
  ``MIN_BEND_RADIUS`` (3 mm: no folds; the bound and the bend reached are in
  its metadata);
* kept only within 3 mm of the traced points' footprint: forward to the
  alveolar ridge and back towards the soft palate as far as the points go,
  never extrapolated further.

The surface is stored in the frame of the recordings it came from;
``transform`` (a similarity, e.g. the speech recording's alignment onto the
tongue model) carries it into another frame, and every query takes points in
that other frame.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tonguevis.errors import TonguevisError

GRID_STEP = 1e-3  # m
FOOTPRINT_MARGIN = 3e-3  # m: how far beyond the traced points the surface reaches
OUTLIER_SIGMAS = 3.0
#: No fold: the fitted palate bends nowhere more tightly than this radius (m).  The alveolar ridge, a
#: real palate's tightest bend, is 3-5 mm; the traces' own jitter made folds of 0.15 mm radius.
MIN_BEND_RADIUS = 3e-3
#: The seam (m) over which a traced palate blends into the generic one behind and beside it.
SEAM = 3e-3
#: m: how far outward the generic roof eases back from meeting the traced edge (joined_palate)
FEATHER = 10e-3
#: Grid cells where a traced and the generic palate must both lie before they are joined.
MIN_OVERLAP_CELLS = 20
#: m: a grid cell's support is the count of trace points (as traced, not mirrored) within this distance of it
SUPPORT_RADIUS = 2.5e-3
#: Trace points within SUPPORT_RADIUS that make a cell traced: a probe drawn past it at a clinician's pace leaves
#: 30-50 at 100 Hz (OSN12's midsagittal trace: 14 a mm); the scribble's few strokes behind the traced hard palate
#: leave 0-18, too few to say where the soft palate is (it also lifts in speech).
MIN_SUPPORT = 20


class PalateError(TonguevisError):
    """A palate trace or file that cannot make a palate."""


def check_mesh_path(path) -> Path:
    """``path`` if its extension names a mesh format meshio writes (.stl, .obj, .vtk, .ply ...),
    else :class:`PalateError` naming the file (checked before the work, not after it)."""
    import meshio

    path = Path(path)
    if path.suffix.lower() not in meshio.extension_to_filetypes:
        raise PalateError(f"{path.suffix or 'no extension'} is not a surface mesh format; give the palate file "
                          "an extension such as .stl, .obj, .vtk or .ply (the grid is written beside it as "
                          "<name>.palate.npz)", path)
    return path


@dataclass
class PalateSurface:
    """A palate as a height field z = h(x, y), metres, in its own (recording) frame.

    x : (nx,) and y : (ny,) increasing grid coordinates; z : (ny, nx) heights,
    NaN outside the palate's footprint.  ``rotation`` (3, 3), ``scale`` and
    ``translation`` (3,) map its frame into the frame queries are made in:
    p_query = scale · R p_own + t (identity by default).  ``metadata``: fit
    figures (``rms_m``, point counts, sources).
    support : (ny, nx) the trace points within :data:`SUPPORT_RADIUS` of each cell (a fitted palate; None
        for a mesh read as it is): where it is at least :data:`MIN_SUPPORT` the palate was traced.
    traced : (ny, nx) bool, the cells traced (a speaker's palate placed for a simulation; None: unknown).
    lift_shape : (ny, nx) how much of a velum lift each cell takes (0 in front of the soft palate, 1 on it;
        None: a rigid palate): :meth:`clearance` and :meth:`lifted` add ``lift`` times it to the heights.
    """

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    scale: float = 1.0
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    metadata: dict[str, Any] = field(default_factory=dict)
    support: np.ndarray | None = None
    traced: np.ndarray | None = None
    lift_shape: np.ndarray | None = None

    # ---------------------------------------------------------------- frames
    def transformed(self, rotation: np.ndarray, scale: float, translation: np.ndarray) -> "PalateSurface":
        """The same palate seen through one more similarity p -> scale · R p + t (applied after its own)."""
        rot = np.asarray(rotation, dtype=np.float64)
        return PalateSurface(self.x, self.y, self.z, rot @ self.rotation, float(scale) * self.scale,
                             float(scale) * rot @ self.translation + np.asarray(translation, dtype=np.float64),
                             dict(self.metadata), self.support, self.traced, self.lift_shape)

    def with_grid(self, z: np.ndarray, **fields) -> "PalateSurface":
        """The same palate (grid, placement) with heights ``z`` (ny, nx) and ``fields`` (``traced=``,
        ``lift_shape=``, ``metadata=``...) replaced."""
        import dataclasses

        return dataclasses.replace(self, z=np.asarray(z, dtype=np.float64), **fields)

    def lifted(self, lift: float) -> "PalateSurface":
        """The palate with its velum lifted by ``lift`` m (times :attr:`lift_shape`); itself when nothing lifts."""
        if self.lift_shape is None or not lift:
            return self
        return self.with_grid(self.z + float(lift) * self.lift_shape / self.scale)

    def _to_own(self, points: np.ndarray) -> np.ndarray:
        return ((np.asarray(points, dtype=np.float64) - self.translation) @ self.rotation) / self.scale

    def _from_own(self, points: np.ndarray) -> np.ndarray:
        return self.scale * np.asarray(points) @ self.rotation.T + self.translation

    # ---------------------------------------------------------------- queries
    def _interp(self, xy: np.ndarray, grid: np.ndarray | None = None):
        """Height (k,) and slopes (k, 2) of the own-frame (k, 2) points (bilinear; NaN outside) of ``grid``
        (default: the heights ``z``; the same interpolation for any field on the grid)."""
        x, y, z = self.x, self.y, (self.z if grid is None else grid)
        fx = (xy[:, 0] - x[0]) / (x[1] - x[0])
        fy = (xy[:, 1] - y[0]) / (y[1] - y[0])
        inside = (fx >= 0) & (fx <= len(x) - 1) & (fy >= 0) & (fy <= len(y) - 1)
        fx, fy = np.where(inside, fx, 0.0), np.where(inside, fy, 0.0)  # a NaN point (a dropout): NaN, no cast warning
        i = np.clip(np.floor(fx).astype(int), 0, len(x) - 2)
        j = np.clip(np.floor(fy).astype(int), 0, len(y) - 2)
        tx, ty = np.clip(fx - i, 0, 1), np.clip(fy - j, 0, 1)
        z00, z10, z01, z11 = z[j, i], z[j, i + 1], z[j + 1, i], z[j + 1, i + 1]
        h = (1 - ty) * ((1 - tx) * z00 + tx * z10) + ty * ((1 - tx) * z01 + tx * z11)
        dx = ((1 - ty) * (z10 - z00) + ty * (z11 - z01)) / (x[1] - x[0])
        dy = ((1 - tx) * (z01 - z00) + tx * (z11 - z10)) / (y[1] - y[0])
        h = np.where(inside, h, np.nan)
        return h, np.column_stack([dx, dy])

    def clearance(self, points: np.ndarray, lift=None) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance (k,) below the palate, m (negative: inside it), and outward normals (k, 3).

        points : (k, 3) in the query frame.  The distance is the vertical gap
        times the cosine of the palate's slope there (exact for a plane); NaN
        where the point lies outside the palate's footprint.  Normals point
        down, away from the palate into the mouth, in the query frame.
        lift : the velum's lift, m in the query frame (a number, or (k,) one per point: each point's frame's);
        None or 0: the palate at rest.
        """
        own = self._to_own(points)
        h, grad = self._interp(own[:, :2])
        if lift is not None and self.lift_shape is not None:
            g, g_grad = self._interp(own[:, :2], self.lift_shape)
            amount = np.asarray(lift, dtype=np.float64) / self.scale
            h = h + amount * g
            grad = grad + np.asarray(amount)[..., None] * g_grad
        normal_own = np.column_stack([grad, -np.ones(len(own))])
        norm = np.linalg.norm(normal_own, axis=1)
        gap = (h - own[:, 2]) / norm * self.scale
        normal = (normal_own / norm[:, None]) @ self.rotation.T
        return gap, normal

    # ---------------------------------------------------------------- meshes
    def triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) vertices in the query frame and (f, 3) triangles of the surface (for drawing and export)."""
        nx, ny = len(self.x), len(self.y)
        gx, gy = np.meshgrid(self.x, self.y)
        pts = np.column_stack([gx.ravel(), gy.ravel(), self.z.ravel()])
        ok = np.isfinite(pts[:, 2])
        index = np.full(len(pts), -1)
        index[ok] = np.arange(ok.sum())
        ids = np.arange(nx * ny).reshape(ny, nx)
        quads = np.stack([ids[:-1, :-1], ids[:-1, 1:], ids[1:, 1:], ids[1:, :-1]], axis=-1).reshape(-1, 4)
        tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
        tris = tris[np.all(ok[tris], axis=1)]
        return self._from_own(pts[ok]), index[tris]

    def save(self, path) -> None:
        """Write the surface mesh (.stl, .obj, .vtk, .ply ... by meshio; metres) and the grid beside it
        (``<name>.palate.npz``, read back by :meth:`load`), each through a temporary file.
        Raises :class:`PalateError` for a file type that is not a surface mesh's."""
        import meshio

        from tonguevis._files import atomic_write

        path = check_mesh_path(path)
        pts, tris = self.triangles()
        atomic_write(path, lambda tmp: meshio.write(tmp, meshio.Mesh(pts, [("triangle", tris)])))
        meta = json.dumps(self.metadata, default=float)
        extra = {name: np.asarray(getattr(self, name)) for name in ("support", "traced", "lift_shape")
                 if getattr(self, name) is not None}
        atomic_write(grid_path(path), lambda tmp: np.savez_compressed(
            tmp, x=self.x, y=self.y, z=self.z, rotation=self.rotation, scale=self.scale,
            translation=self.translation, meta=np.array(meta), **extra))

    @classmethod
    def load(cls, path) -> "PalateSurface":
        """A palate written by :meth:`save` (its grid file), or any surface mesh (sampled from below)."""
        path = Path(path)
        grid = grid_path(path) if not path.name.endswith(".palate.npz") else path
        if grid.exists():
            import zipfile

            try:
                with np.load(grid, allow_pickle=False) as d:
                    extra = {name: np.array(d[name]) for name in ("support", "traced", "lift_shape") if name in d}
                    surface = cls(d["x"], d["y"], d["z"], d["rotation"], float(d["scale"]), d["translation"],
                                  json.loads(str(d["meta"])), **extra)
            except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
                raise PalateError(f"cannot read the palate grid: {exc}", grid) from exc
            return _checked(surface, grid)
        return from_mesh(path)


def generic_palate() -> PalateSurface:
    """The shipped generic palate (``meshes/palate.stl``), already in the model frame of the shipped tongue.

    Read once per process (and again if the file changes): every simulation with a palate places it,
    and reading the mesh cost more than the contact solve of the demo.  Each call returns its own copy.
    """
    import copy

    from tonguevis.mesh.default import context_surface_path

    path = context_surface_path("palate")
    stat = Path(path).stat()
    surface = _generic_from(str(path), stat.st_mtime_ns, stat.st_size)
    return PalateSurface(surface.x.copy(), surface.y.copy(), surface.z.copy(), metadata=copy.deepcopy(surface.metadata))


@functools.lru_cache(maxsize=2)
def _generic_from(path: str, mtime_ns: int, size: int) -> PalateSurface:
    """The generic palate from the shipped file as it is (mtime, size: the cache's key)."""
    surface = from_mesh(path)
    surface.metadata.update({"frame": "model", "generic": True})
    return surface


def load_palate(spec) -> PalateSurface:
    """A palate from ``"generic"`` (the shipped one, model frame) or a file (a speaker's, recording frame).

    The shipped file itself (``meshes/palate.stl``) is the generic palate too: read as a
    speaker's, it would be moved by the recording's alignment.
    """
    if isinstance(spec, PalateSurface):
        return spec
    if str(spec) == "generic" or _is_generic_file(spec):
        return generic_palate()
    surface = PalateSurface.load(spec)
    surface.metadata["file"] = str(spec)  # which file it came from (its "source" lists the traces)
    return surface


def _is_generic_file(path) -> bool:
    from tonguevis.mesh.default import context_surface_path

    try:
        return Path(path).resolve() == context_surface_path("palate").resolve()
    except (OSError, ValueError):
        return False


def grid_path(mesh_path) -> Path:
    """The grid file stored beside a palate mesh: ``palate.stl`` -> ``palate.palate.npz``."""
    mesh_path = Path(mesh_path)
    return mesh_path.with_name(mesh_path.stem + ".palate.npz")


def from_mesh(path, step: float = GRID_STEP) -> PalateSurface:
    """A palate height field from any surface mesh: at each grid point, the lowest surface above it."""
    import meshio

    try:
        mesh = meshio.read(path)
    except Exception as exc:  # meshio raises many kinds on bad files
        if _is_recording(path):
            raise PalateError("a recording (palate traces?), not a palate surface: make one from the traces "
                              "with `tonguevis palate TRACE.tsv ... --out palate.stl` (in the app, File ▸ Fit "
                              "palate from traces…), then give palate.stl", path) from exc
        raise PalateError(f"cannot read a surface mesh: {exc}", path) from exc
    tris = [c.data for c in mesh.cells if c.type == "triangle"]
    if not tris:
        raise PalateError("the mesh has no triangles", path)
    return _checked(_height_field(np.asarray(mesh.points, dtype=np.float64)[:, :3], np.concatenate(tris), step,
                                  {"source": [str(path)]}), path)


def _is_recording(path) -> bool:
    """Whether ``path`` is a recording tonguevis reads (by its content or extension), e.g. palate traces."""
    from tonguevis.errors import RecordingError
    from tonguevis.io.registry import detect_format

    try:
        detect_format(path)
    except (RecordingError, OSError):
        return False
    return True


def _checked(surface: PalateSurface, path) -> PalateSurface:
    """``surface`` if it is a usable height field (a grid of at least 2 x 2 with some height), else PalateError."""
    x, y, z = (np.asarray(a) for a in (surface.x, surface.y, surface.z))
    if x.ndim != 1 or y.ndim != 1 or len(x) < 2 or len(y) < 2 or z.shape != (len(y), len(x)):
        raise PalateError(f"not a palate surface: seen from below it covers no area (grid {z.shape}, "
                          f"{len(x)} x {len(y)} points)", path)
    if not np.isfinite(z).any():
        raise PalateError("not a palate surface: no triangle faces down onto the grid", path)
    return surface


def _height_field(points, tris, step, metadata) -> PalateSurface:
    """Lowest z of the triangles over each grid point (x, y).

    The grid is regular, so each triangle visits only the grid points of its bounding box
    (index ranges, not a search of the whole grid); all triangles' boxes at once (the shipped
    palate's 0.2 s loop over its triangles took longer than a whole simulation)."""
    lo, hi = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
    x = np.arange(lo[0], hi[0] + step / 2, step)
    y = np.arange(lo[1], hi[1] + step / 2, step)
    z = np.full((len(y), len(x)), np.inf)
    a, b, c = (points[tris[:, k]] for k in range(3))
    box_lo = np.minimum(np.minimum(a[:, :2], b[:, :2]), c[:, :2])
    box_hi = np.maximum(np.maximum(a[:, :2], b[:, :2]), c[:, :2])
    first = np.maximum(np.ceil((box_lo - lo) / step - 1e-9).astype(np.int64), 0)
    last = np.minimum(np.floor((box_hi - lo) / step + 1e-9).astype(np.int64), [len(x) - 1, len(y) - 1])
    v0, v1 = b[:, :2] - a[:, :2], c[:, :2] - a[:, :2]
    den = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
    # Every (triangle, grid point of its box) pair at once, in runs per triangle.
    span = np.maximum(last - first + 1, 0)
    count = np.where(np.abs(den) < 1e-18, 0, span[:, 0] * span[:, 1])
    tri = np.repeat(np.arange(len(tris)), count)
    local = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
    ix = first[tri, 0] + local % span[tri, 0]
    iy = first[tri, 1] + local // span[tri, 0]
    wx, wy = x[ix] - a[tri, 0], y[iy] - a[tri, 1]
    dt, w0, w1 = den[tri], v0[tri], v1[tri]
    u = (wx * w1[:, 1] - wy * w1[:, 0]) / dt
    v = (w0[:, 0] * wy - w0[:, 1] * wx) / dt
    inside = (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9)
    at = tri[inside]
    zz = a[at, 2] + u[inside] * (b[at, 2] - a[at, 2]) + v[inside] * (c[at, 2] - a[at, 2])
    np.minimum.at(z.reshape(-1), iy[inside] * len(x) + ix[inside], zz)
    z = np.where(np.isfinite(z), z, np.nan)
    return PalateSurface(x, y, z, metadata=metadata)


def bend_curvature(z: np.ndarray, step: float) -> float:
    """The largest principal curvature (1/m) of the surface z(x, y) (ny, nx) on a grid of ``step`` m, the
    surface's own (the shape operator's eigenvalues from central differences; NaN cells and their neighbours
    left out); 0 without any.  Not the height field's Hessian, which overstates a bend by (1 + slope²)^1.5
    where the surface is steep (behind the incisors)."""
    zx = (z[1:-1, 2:] - z[1:-1, :-2]) / (2 * step)
    zy = (z[2:, 1:-1] - z[:-2, 1:-1]) / (2 * step)
    zxx = (z[1:-1, 2:] - 2 * z[1:-1, 1:-1] + z[1:-1, :-2]) / step ** 2
    zyy = (z[2:, 1:-1] - 2 * z[1:-1, 1:-1] + z[:-2, 1:-1]) / step ** 2
    zxy = (z[2:, 2:] - z[2:, :-2] - z[:-2, 2:] + z[:-2, :-2]) / (4 * step ** 2)
    w2 = 1.0 + zx ** 2 + zy ** 2
    # a graph's mean and Gaussian curvature (do Carmo, "Differential Geometry of Curves and Surfaces", 3-3)
    mean = ((1 + zy ** 2) * zxx - 2 * zx * zy * zxy + (1 + zx ** 2) * zyy) / (2 * w2 ** 1.5)
    gauss = (zxx * zyy - zxy ** 2) / w2 ** 2
    spread = np.sqrt(np.maximum(mean ** 2 - gauss, 0.0))
    k = np.maximum(np.abs(mean + spread), np.abs(mean - spread))
    k = k[np.isfinite(k)]
    return float(k.max()) if k.size else 0.0


def fit_palate(points: np.ndarray, midline_y: float | None = None, smoothing: float = 5e-7,
               step: float = GRID_STEP, sources: list[str] | None = None,
               min_radius: float | None = MIN_BEND_RADIUS) -> PalateSurface:
    """Fit a palate to (k, 3) trace points (metres, x anterior, y left, z up); see the module docstring.

    midline_y : the midline's y (default: the points' mirror symmetry, :func:`symmetry_midline`, else
        their median y; ``metadata["midline_from"]`` says which).
    smoothing : the thin-plate spline's smoothing to start from (m²; larger is smoother); raised
        tenfold, then halved back as far as the bound allows, until the surface bends nowhere
        more tightly than ``min_radius`` (m; None: no bound).
    The fit's figures are in ``metadata``: ``rms_m`` (trace points kept, to the
    surface), ``points``, ``kept``, ``midline_y``, ``smoothing``, ``min_bend_radius_m`` (the
    bound) and ``bend_radius_m`` (the tightest bend reached).
    """
    how = "given"
    if midline_y is None:
        midline_y = symmetry_midline(points)
        how = "the traces' mirror symmetry" if midline_y is not None else "the trace points' median"
    surface = _fit_palate(points, midline_y, smoothing, step, sources)
    surface.metadata["midline_from"] = how
    if min_radius is None:
        return surface
    bound = 1.0 / min_radius
    tried = [(smoothing, surface)]
    while bend_curvature(np.asarray(surface.z), step) > bound and smoothing < 1.0:
        smoothing *= 10.0
        surface = _fit_palate(points, midline_y, smoothing, step, sources)
        tried.append((smoothing, surface))
    if len(tried) > 1 and bend_curvature(np.asarray(surface.z), step) <= bound:
        low = tried[-2][0]
        for factor in (0.5, 0.25):  # back down within the last decade: the least smoothing that keeps the bound
            candidate = _fit_palate(points, midline_y, smoothing * factor, step, sources)
            if smoothing * factor > low and bend_curvature(np.asarray(candidate.z), step) <= bound:
                surface = candidate
    reached = bend_curvature(np.asarray(surface.z), step)
    surface.metadata.update({"midline_from": how, "min_bend_radius_m": float(min_radius),
                             "bend_radius_m": float(1.0 / reached) if reached > 0 else float("inf")})
    return surface


def _fit_palate(points: np.ndarray, midline_y: float | None, smoothing: float, step: float,
                sources: list[str] | None) -> PalateSurface:
    """One thin-plate fit of :func:`fit_palate` at the given smoothing."""
    from scipy.interpolate import RBFInterpolator

    pts = np.asarray(points, dtype=np.float64)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 20:
        raise PalateError(f"a palate needs at least 20 trace points, got {len(pts)}")
    y0 = float(np.median(pts[:, 1]) if midline_y is None else midline_y)
    keep = np.ones(len(pts), dtype=bool)
    for _ in range(4):
        both = _binned(_mirrored(pts[keep], y0), step)
        spline = RBFInterpolator(both[:, :2], both[:, 2], kernel="thin_plate_spline",
                                 smoothing=smoothing, degree=1)
        resid = pts[:, 2] - spline(pts[:, :2])
        scale = 1.4826 * np.median(np.abs(resid[keep] - np.median(resid[keep])))
        new = np.abs(resid - np.median(resid[keep])) <= OUTLIER_SIGMAS * max(scale, 1e-5)
        if np.array_equal(new, keep):
            break
        keep = new
    kept = _mirrored(pts[keep], y0)
    lo = kept[:, :2].min(axis=0) - FOOTPRINT_MARGIN
    hi = kept[:, :2].max(axis=0) + FOOTPRINT_MARGIN
    x = np.arange(lo[0], hi[0] + step / 2, step)
    half = max(abs(hi[1] - y0), abs(y0 - lo[1]))
    y = y0 + np.arange(-np.ceil(half / step), np.ceil(half / step) + 1) * step
    gx, gy = np.meshgrid(x, y)
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    z = spline(grid)
    from scipy.spatial import cKDTree

    near = cKDTree(kept[:, :2]).query(grid, distance_upper_bound=FOOTPRINT_MARGIN)[0] <= FOOTPRINT_MARGIN
    z = np.where(near, z, np.nan).reshape(len(y), len(x))
    # where the probe went (not its mirror image: the mirrored side is the fit's estimate)
    support = cKDTree(pts[keep, :2]).query_ball_point(grid, SUPPORT_RADIUS, return_length=True).reshape(len(y), len(x))
    surface = PalateSurface(x, y, z, metadata={"points": int(len(pts)), "kept": int(keep.sum()),
                                               "midline_y": y0, "smoothing": smoothing,
                                               "source": list(sources or [])}, support=support.astype(np.int32))
    gap, _ = surface.clearance(pts[keep])
    surface.metadata["rms_m"] = float(np.sqrt(np.nanmean(gap ** 2)))
    return surface


def joined_palate(traced: PalateSurface, generic: PalateSurface, step: float = GRID_STEP,
                  seam: float = SEAM, feather: float = FEATHER) -> PalateSurface:
    """A whole roof: ``traced`` (a speaker's palate, placed in the query frame) where it was traced,
    ``generic`` (the same frame) behind and beside it, moved up or down to meet it.

    Both become height fields on one grid of ``step`` m in the query frame (the lowest surface
    above each point).  The generic palate is moved vertically by the median height difference
    where both are defined; where they still differ along the traced part's edge, the generic roof
    is bent to meet it, easing back over ``feather`` m outward, and the two blend over ``seam`` m
    inside the edge (smooth steps), so the roof is continuous and without a cliff.  The result is in the query frame (identity
    transform); ``metadata["joined"]``: {"generic_shift_mm", "traced_share", "seam_mm"}.
    """
    from scipy.ndimage import distance_transform_edt, gaussian_filter

    pts_t, tri_t = traced.triangles()
    pts_g, tri_g = generic.triangles()
    if len(tri_t) == 0:
        return traced
    both = np.concatenate([pts_t[:, :2], pts_g[:, :2]])
    lo, hi = both.min(axis=0), both.max(axis=0)
    # one grid for both: each surface's lowest z over it, the grid spanning both footprints
    corner = np.array([[lo[0], lo[1], 0.0], [hi[0], hi[1], 0.0], [lo[0], hi[1], 0.0]])
    grid_t = _height_field(np.concatenate([pts_t, corner]), tri_t, step, {})
    grid_g = _height_field(np.concatenate([pts_g, corner]), tri_g, step, {})
    h_t, h_g = np.asarray(grid_t.z), np.asarray(grid_g.z)
    overlap = np.isfinite(h_t) & np.isfinite(h_g)
    if overlap.sum() < MIN_OVERLAP_CELLS:  # the generic roof is not where this palate is: nothing to join
        return traced
    shift = float(np.median(h_t[overlap] - h_g[overlap]))
    moved = h_g + shift
    inside = np.isfinite(h_t)
    # Where the two roofs still differ along the traced part's edge (by up to 10 mm on real traces: the
    # shapes differ, not only their heights), the generic roof is bent to meet the traced edge and
    # eases back to itself over ``feather`` m outward: the traced heights are kept, no cliff at the seam.
    mismatch = np.where(overlap, h_t - moved, np.nan)
    bend = np.zeros_like(moved)
    if np.isfinite(mismatch).any():
        nearest = distance_transform_edt(~np.isfinite(mismatch), return_distances=False, return_indices=True)
        edge = gaussian_filter(mismatch[tuple(nearest)], sigma=2.0)  # the edge's mismatch, smoothed along it
        out = np.clip(1.0 - distance_transform_edt(~inside) * step / max(feather, 1e-12), 0.0, 1.0)
        bend = edge * out * out * (3.0 - 2.0 * out)  # a smooth step from the edge (1) to feather away (0)
    depth = distance_transform_edt(inside) * step  # m from the traced part's edge, inward
    weight = np.clip(depth / max(seam, 1e-12), 0.0, 1.0)
    weight = weight * weight * (3.0 - 2.0 * weight)  # a smooth step
    met = moved + bend
    z = np.where(inside & np.isfinite(met), weight * h_t + (1.0 - weight) * met, np.where(inside, h_t, met))
    metadata = {**traced.metadata, "joined": {"generic_shift_mm": 1e3 * shift,
                                              "traced_share": float(inside.sum() / max(np.isfinite(z).sum(), 1)),
                                              "seam_mm": 1e3 * seam, "feather_mm": 1e3 * feather}}
    return PalateSurface(grid_t.x, grid_t.y, z, metadata=metadata)


def _binned(points: np.ndarray, step: float) -> np.ndarray:
    """One point per occupied (x, y) cell of side ``step``: the cell's mean x, y and median z.

    Traces hold thousands of samples along a few paths; the spline needs their
    shape, not every sample (its solve grows with the cube of the count).
    """
    cells = np.floor(points[:, :2] / step).astype(np.int64)
    _, inverse, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    order = np.argsort(inverse, kind="stable")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    xy = np.add.reduceat(points[order, :2], starts, axis=0) / counts[:, None]
    z = np.array([np.median(points[order[a:a + n], 2]) for a, n in zip(starts, counts)])
    return np.column_stack([xy, z])


def _mirrored(points: np.ndarray, y0: float) -> np.ndarray:
    mirror = points.copy()
    mirror[:, 1] = 2 * y0 - mirror[:, 1]
    return np.concatenate([points, mirror])


def trace_points(recording, probe: str = "PROBE") -> np.ndarray:
    """(k, 3) valid positions of the probe sensor of a palate-trace recording, head-corrected when it can be."""
    from tonguevis.errors import RecordingError
    from tonguevis.preprocess.correction import head_corrected

    if probe not in recording.sensors:
        raise RecordingError(f"no probe sensor {probe!r} (sensors: {', '.join(recording.sensor_names)}); "
                             "name it with --probe SENSOR", recording.metadata.get("file"))
    rec = head_corrected(recording)
    pts = rec.sensors[probe]
    return pts[np.all(np.isfinite(pts), axis=1)]


#: m: how far either side of the trace points' median y the mirror plane is looked for, and the step.
MIDLINE_SEARCH, MIDLINE_STEP = 15e-3, 0.25e-3
#: m: a mirrored trace point is compared with the traced points within this distance (in x, y).
MIDLINE_PAIRING = 1.5e-3
#: The least share of the trace points that must find a mirrored partner for the symmetry to tell.
MIDLINE_MIN_PAIRED = 0.3
#: The best plane's mean height mismatch, as a share of the points' height spread (std), above which the
#: traces show no symmetry (OSN12's traces: 0.3; one side of a vault traced: over 2).
MIDLINE_MAX_MISMATCH = 0.5


def symmetry_midline(points: np.ndarray) -> float | None:
    """The midline's y (m) from the palate's own mirror symmetry, or None if the traces cannot tell.

    points : (k, 3) trace points, metres (x anterior, y left, z up).
    Each candidate plane y = y0 (every ``MIDLINE_STEP`` within ``MIDLINE_SEARCH`` of the median y)
    mirrors the points; the plane whose mirror images lie at the traced heights best (the mean
    height difference to the traced points within ``MIDLINE_PAIRING`` in x, y) is the midline.  A
    palate is symmetric about its midline, where the lateral tongue sensors are not: on the shared
    Opti-Speech traces (OSN12) the lateral sensors, pushed aside by the probe, put the midline 8.3 mm
    right, the symmetry 5.5 mm (the coronal trace's crest is at 5-5.5 mm), and the fit's RMS fell from
    0.88 to 0.76 mm.  None when fewer than ``MIDLINE_MIN_PAIRED`` of the points find a partner at the best
    plane, or when the best plane's mirror images still miss the traced heights by half their spread
    (a trace of one side only): the caller's fallback decides then.
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 20:
        return None
    tree = cKDTree(pts[:, :2])
    median = float(np.median(pts[:, 1]))
    best, best_cost = None, np.inf
    for y0 in median + np.arange(-MIDLINE_SEARCH, MIDLINE_SEARCH + MIDLINE_STEP / 2, MIDLINE_STEP):
        mirrored = np.column_stack([pts[:, 0], 2.0 * y0 - pts[:, 1]])
        distance, index = tree.query(mirrored, distance_upper_bound=MIDLINE_PAIRING)
        # only points off the plane count: one on it is trivially its own mirror image
        paired = np.isfinite(distance) & (np.abs(pts[:, 1] - y0) > 2 * MIDLINE_PAIRING)
        if paired.sum() < MIDLINE_MIN_PAIRED * len(pts):
            continue
        cost = float(np.mean(np.abs(pts[paired, 2] - pts[index[paired], 2])))
        if cost < best_cost:
            best, best_cost = float(y0), cost
    # Mirror images that still miss the traced heights by half their spread: no symmetry found (one side)
    return best if best_cost <= MIDLINE_MAX_MISMATCH * float(np.std(pts[:, 2])) else None


def midline_of(recording) -> float | None:
    """The midline's y from a recording's lateral tongue sensors (mean of TL and TR), if it has both."""
    if "TL" in recording.sensors and "TR" in recording.sensors:
        both = np.concatenate([recording.sensors["TL"], recording.sensors["TR"]])
        return float(np.nanmean(both[:, 1]))
    return None


#: Traces recorded without head references are registered to each other by their shape
#: (:func:`rigid_fit_to_surface`); a trace's tilt about an axis is estimated only where its overlap with the
#: others spreads this far (std, m) across that axis: a line drawn across the palate cannot tell its pitch.
MIN_TILT_SPREAD = 5e-3
#: Trace points a trace must share with the others (within SUPPORT_RADIUS, x-y) to be registered to them.
MIN_OVERLAP = 50


def rigid_fit_to_surface(points: np.ndarray, surface: PalateSurface, others: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, dict] | None:
    """The small rigid motion (rotation (3, 3), translation (3,), info) that lays ``points`` (k, 3) onto
    ``surface`` where they overlap the trace points ``others`` (n, 3) (within :data:`SUPPORT_RADIUS` in x-y):
    a vertical shift, and a pitch and a roll about the overlap's centre where it spreads at least
    :data:`MIN_TILT_SPREAD` across their axes, by least squares on the vertical gaps (points more than 3
    robust sigmas off left out, as in the fit).  None with fewer than :data:`MIN_OVERLAP` points in the overlap.
    info: ``overlap`` (points), ``shift_mm``, ``pitch_deg``, ``roll_deg``, ``rms_before_mm``, ``rms_after_mm``
    (the vertical gaps of the points kept).  ``surface`` as :func:`fit_palate` makes it (its own frame the
    traces'); metres."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64)
    height, _ = surface._interp(pts[:, :2])  # a surface fitted in the traces' frame: its own is the query frame
    near = cKDTree(np.asarray(others)[:, :2]).query(pts[:, :2], distance_upper_bound=SUPPORT_RADIUS)[0]
    ok = np.isfinite(height) & (near <= SUPPORT_RADIUS)
    if ok.sum() < MIN_OVERLAP:
        return None
    p, gap = pts[ok], height[ok] - pts[ok, 2]
    centre = p.mean(axis=0)
    tilts = [axis for axis in (0, 1) if np.std(p[:, axis]) >= MIN_TILT_SPREAD]  # 0: pitch (along x), 1: roll
    design = np.column_stack([np.ones(len(p))] + [p[:, axis] - centre[axis] for axis in tilts])
    keep = np.ones(len(p), dtype=bool)
    for _ in range(4):
        coef = np.linalg.lstsq(design[keep], gap[keep], rcond=None)[0]
        resid = gap - design @ coef
        scale = 1.4826 * np.median(np.abs(resid[keep] - np.median(resid[keep])))
        new = np.abs(resid - np.median(resid[keep])) <= OUTLIER_SIGMAS * max(scale, 1e-5)
        if np.array_equal(new, keep):
            break
        keep = new
    slope = dict(zip(tilts, coef[1:]))
    pitch = -np.arcsin(np.clip(slope.get(0, 0.0), -1, 1))  # z gains slope·(x - x̄): a turn about y
    roll = np.arcsin(np.clip(slope.get(1, 0.0), -1, 1))  # z gains slope·(y - ȳ): a turn about x
    cp, sp, cr, sr = np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    rotation = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]]) @ np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    translation = centre - rotation @ centre + np.array([0.0, 0.0, coef[0]])
    info = {"overlap": int(ok.sum()), "shift_mm": float(1e3 * coef[0]), "pitch_deg": float(np.degrees(pitch)),
            "roll_deg": float(np.degrees(roll)), "rms_before_mm": float(1e3 * np.sqrt(np.mean(gap[keep] ** 2))),
            "rms_after_mm": float(1e3 * np.sqrt(np.mean(resid[keep] ** 2)))}
    return rotation, translation, info
