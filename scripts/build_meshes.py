"""Build the embedded default meshes: a parametric adult tongue and its context.

Writes to ``meshes/`` (or ``--out``):
- ``tongue.vtu``: tetrahedral tongue (metres; x anterior, y left, z up; the mesh
  floor at z = 0, the tip at x = 0, symmetric about y = 0), about 1,800 nodes and
  8,600 tets like the paper's ArtiSynth mesh;
- ``tongue_landmarks.json``: sensor nodes (TT, TB, TD, TBK, TL, TR) and the five
  anchors, found by :func:`tonguevis.mesh.find_landmarks`;
- ``jaw.stl``: lower dental arch (teeth and gum as one U-shaped band) around the
  tongue; ``palate.stl``: a dome 5-15 mm above the dorsum.

Method: the midsagittal profile (dorsum and underside heights) and the maximal
half-width are monotone splines of the distance s behind the tip, with
proportions of the ArtiSynth tongue measured in our frame (DESIGN.md, "Embedded
default data").  Each cross-section is a superellipse-like outline, widest at
about 40 % of its height, tapering towards a narrower floor and a domed top.
The solid is the zero level set of a field sampled on a 0.5 mm grid (marching
cubes through VTK), Taubin-smoothed, then tetrahedralised with fTetWild
(pytetwild).  The surface, jaw and palate are deterministic (same bytes every
run); fTetWild is not bit-reproducible even on one thread (two runs gave 1,719
and 1,706 nodes), so the committed ``meshes/tongue.vtu`` and its landmarks are
the reference: rebuild only to change the design, and commit both together.

Usage:  python scripts/build_meshes.py [--out DIR] [--render PNG] [--no-render] [--context-only]
"""

from __future__ import annotations

import argparse
import hashlib
import logging
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tonguevis.mesh import TetMesh  # noqa: E402
from tonguevis.mesh.quality import tet_quality  # noqa: E402

MM = 1e-3

# Proportions in mm against s = distance behind the tip (see module docstring).
TOP_Z = [(0, 45.5), (2, 48.5), (6, 50.5), (15, 52.5), (25, 54.0), (35, 55.5), (42, 55.5),
         (50, 54.0), (56, 51.5), (60, 48.5), (65, 42.0), (70, 33.0), (74, 25.0), (77, 19.0)]
BOTTOM_Z = [(0, 45.5), (2, 42.0), (8, 39.0), (14, 35.5), (18, 33.0), (19.5, 28.0), (21.5, 17.0),
            (24, 7.0), (27, 2.0), (31, 0.0), (65, 0.0), (70, 2.5), (74, 7.0), (77, 12.0)]
HALF_WIDTH = [(0, 9.0), (5, 11.0), (10, 12.8), (15, 14.0), (20, 14.5), (30, 17.0), (40, 23.0),
              (50, 28.0), (60, 32.5), (67, 33.5), (72, 30.0), (77, 24.5)]
# Height fraction of the widest point, and floor width as a fraction of the widest.
WIDEST_AT = [(0, 0.5), (18, 0.5), (26, 0.42), (77, 0.42)]
FLOOR_WIDTH = [(0, 0.85), (18, 0.85), (26, 0.6), (77, 0.6)]
LENGTH = 76.0          # mm, tip to the back of the root
TIP_RADIUS = 3.0       # mm over which the tip rounds off
ROOT_RADIUS = 6.0      # mm over which the root rounds off
TOP_EXPONENT = 1.6     # superellipse exponent of the dorsum half of a section
BOTTOM_EXPONENT = 2.5  # ... and of the lower half (boxier)
GRID_MM = 0.5          # marching-cubes voxel size

TETWILD_EDGE_FAC = 0.045  # fTetWild ideal edge length, fraction of the bbox diagonal
TETWILD_EPSILON = 4e-3     # envelope, fraction of the bbox diagonal

log = logging.getLogger("build_meshes")


def _spline(knots):
    s, v = np.array(knots, dtype=float).T
    return PchipInterpolator(s, v, extrapolate=True)


def _cap(s: np.ndarray) -> np.ndarray:
    """Rounding factor in [0, 1]: 0 at the tip and root ends, 1 in between."""
    s = np.asarray(s, dtype=float)
    tip = np.sqrt(np.clip(1.0 - np.clip(1.0 - s / TIP_RADIUS, 0, None) ** 2, 0, 1))
    root = np.sqrt(np.clip(1.0 - np.clip((s - (LENGTH - ROOT_RADIUS)) / ROOT_RADIUS, 0, None) ** 2, 0, 1))
    inside = (s >= 0) & (s <= LENGTH)
    return np.where(inside, tip * root, 0.0)


def tongue_field(s: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Implicit field in mm: negative inside the tongue, zero on its surface.

    s : distance behind the tip, y : lateral, z : height above the floor (all mm).
    """
    top, bottom = _spline(TOP_Z)(s), _spline(BOTTOM_Z)(s)
    centre, half_height = 0.5 * (top + bottom), 0.5 * (top - bottom)
    cap = _cap(s)
    half_height = half_height * cap
    width = _spline(HALF_WIDTH)(s) * cap
    widest_at, floor_width = _spline(WIDEST_AT)(s), _spline(FLOOR_WIDTH)(s)
    bottom = centre - half_height
    height = np.maximum(2.0 * half_height, 1e-9)
    t = (z - bottom) / height                                   # 0 at the underside, 1 on top
    upper = np.clip((t - widest_at) / (1.0 - widest_at), 0.0, 1.0)
    lower = np.clip((widest_at - t) / widest_at, 0.0, 1.0)
    shape_top = (1.0 - upper ** TOP_EXPONENT) ** (1.0 / TOP_EXPONENT)
    shape_bottom = (1.0 - lower ** BOTTOM_EXPONENT) ** (1.0 / BOTTOM_EXPONENT) * (1.0 - (1.0 - floor_width) * lower ** 2)
    half = width * np.where(t >= widest_at, shape_top, shape_bottom)
    outside_height = np.maximum(-t, t - 1.0) * height
    field = np.abs(y) - half
    field = np.where(outside_height > 0, np.abs(y) + outside_height, field)
    outside_length = np.maximum(-s, s - LENGTH)
    return np.where(outside_length > 0, np.abs(y) + outside_length + 1.0, field)


def tongue_surface():
    """Watertight, Taubin-smoothed triangle surface of the tongue (trimesh, mm)."""
    import pyvista as pv
    import trimesh
    from trimesh.smoothing import filter_taubin

    pad = 2.0
    s_axis = np.arange(-pad, LENGTH + pad + GRID_MM, GRID_MM)
    y_half = np.arange(0.0, 36.0 + pad, GRID_MM)
    y_axis = np.concatenate([-y_half[:0:-1], y_half])           # symmetric about y = 0
    z_axis = np.arange(-pad, 58.0 + pad, GRID_MM)
    S, Y, Z = np.meshgrid(s_axis, y_axis, z_axis, indexing="ij")
    grid = pv.ImageData(dimensions=S.shape, spacing=(GRID_MM,) * 3,
                        origin=(s_axis[0], y_axis[0], z_axis[0]))
    grid.point_data["f"] = tongue_field(S, Y, Z).ravel(order="F")
    contour = grid.contour([0.0], scalars="f", method="flying_edges").triangulate().clean()
    faces = contour.faces.reshape(-1, 4)[:, 1:]
    surface = trimesh.Trimesh(contour.points.astype(np.float64), faces, process=True)
    parts = surface.split(only_watertight=False)
    surface = max(parts, key=lambda m: m.volume)
    filter_taubin(surface, lamb=0.5, nu=0.53, iterations=30)
    surface.vertices[:, 0] *= -1.0                              # s backwards -> x anterior
    surface.invert()                                            # the flip reversed the winding
    surface.fix_normals()
    if not surface.is_watertight or surface.volume <= 0:
        raise RuntimeError("tongue surface is not watertight")
    return surface


def tetrahedralise(surface) -> TetMesh:
    """fTetWild tet mesh of a trimesh surface in mm -> TetMesh in metres."""
    import pytetwild

    here = os.getcwd()
    with tempfile.TemporaryDirectory() as scratch:            # fTetWild drops __tracked_surface.stl in cwd
        os.chdir(scratch)
        try:
            points, tets = pytetwild.tetrahedralize(
                np.asarray(surface.vertices, dtype=np.float64), np.asarray(surface.faces, dtype=np.int32),
                edge_length_fac=TETWILD_EDGE_FAC, epsilon=TETWILD_EPSILON, num_threads=1, quiet=True)
        finally:
            os.chdir(here)
    mesh = TetMesh(points * MM, tets)
    volumes = mesh.tet_volumes()
    if np.any(volumes < 0):                                     # fTetWild's orientation convention
        mesh.tets[volumes < 0] = mesh.tets[volumes < 0][:, [0, 1, 3, 2]]
    used = np.unique(mesh.tets)
    remap = np.full(mesh.n_nodes, -1)
    remap[used] = np.arange(used.size)
    return TetMesh(mesh.points[used], remap[mesh.tets])


def _tube(path_xy: np.ndarray, z_low: float, z_high: float, thickness: np.ndarray, n_around: int = 16):
    """Closed band of superelliptic cross-section swept along a planar (m, 2) path (mm)."""
    import trimesh

    tangent = np.gradient(path_xy, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.column_stack([tangent[:, 1], -tangent[:, 0]])
    angle = np.linspace(0.0, 2.0 * np.pi, n_around, endpoint=False)
    c, s = np.cos(angle), np.sin(angle)
    ring_u = np.sign(c) * np.abs(c) ** 0.5                      # superellipse, exponent 4
    ring_v = np.sign(s) * np.abs(s) ** 0.5
    half_h, mid_z = 0.5 * (z_high - z_low), 0.5 * (z_high + z_low)
    xy = path_xy[:, None, :] + (thickness[:, None, None] * 0.5) * ring_u[None, :, None] * normal[:, None, :]
    zz = np.broadcast_to(mid_z + half_h * ring_v, xy.shape[:2])
    vertices = np.concatenate([xy, zz[..., None]], axis=2).reshape(-1, 3)
    m = path_xy.shape[0]
    i, j = np.meshgrid(np.arange(m - 1), np.arange(n_around), indexing="ij")
    a, b = i * n_around + j, i * n_around + (j + 1) % n_around
    faces = np.concatenate([np.stack([a, b, b + n_around], -1), np.stack([a, b + n_around, a + n_around], -1)])
    faces = faces.reshape(-1, 3)
    ends = []
    for k, sign in ((0, -1), (m - 1, 1)):                       # fan caps at the two ends
        centre = vertices.shape[0] + len(ends)
        ends.append(vertices[k * n_around:(k + 1) * n_around].mean(axis=0))
        ring = k * n_around + np.arange(n_around)
        cap = np.stack([np.full(n_around, centre), np.roll(ring, -1), ring], -1)
        faces = np.concatenate([faces, cap if sign < 0 else cap[:, ::-1]])
    mesh = trimesh.Trimesh(np.concatenate([vertices, np.array(ends)]), faces, process=True)
    mesh.fix_normals()
    return mesh


def jaw_surface():
    """Lower dental arch: a U band (teeth on gum) around the tongue, mm."""
    u = np.linspace(-1.0, 1.0, 61)
    y = 37.0 * np.sin(0.5 * np.pi * u)                         # arch half-width 37 mm at the molars
    x = 5.0 - 50.0 * (1.0 - np.cos(0.5 * np.pi * u))           # incisors 5 mm ahead of the tip
    thickness = 6.0 + 4.0 * np.abs(u) ** 2                      # incisors thin, molars broad
    return _tube(np.column_stack([x, y]), 27.0, 46.0, thickness)


def palate_surface():
    """Palatal vault: a thin shell 5-15 mm above the dorsum, mm."""
    import trimesh

    top = _spline(TOP_Z)
    xs = np.linspace(8.0, -62.0, 36)                            # alveolar ridge to the soft palate
    v = np.linspace(-1.0, 1.0, 21)
    X, V = np.meshgrid(xs, v, indexing="ij")
    s = np.clip(-X, 0.0, LENGTH)
    half_width = 27.0 + 8.0 * np.clip(s / 45.0, 0.0, 1.0)       # to the upper teeth line
    gap = 13.0 - 6.0 * np.clip(s / 40.0, 0, 1)                  # higher vault in front of the dorsum peak
    crest = top(s) + gap
    crest = np.where(X > 0, crest - 0.6 * X, crest)             # alveolar ridge slopes down in front
    edge = 48.0
    Z = edge + (crest - edge) * (1.0 - np.abs(V) ** 2.5) ** 0.6
    Y = V * half_width
    lower = np.stack([X, Y, Z], -1).reshape(-1, 3)
    upper = lower + np.array([0.0, 0.0, 3.0])                   # 3 mm thick shell
    nx, nv = X.shape
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(nv - 1), indexing="ij")
    a = (i * nv + j).ravel()
    quads = np.stack([a, a + nv, a + nv + 1, a + 1], -1)
    faces = [quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]
    off = lower.shape[0]
    faces += [quads[:, [0, 2, 1]] + off, quads[:, [0, 3, 2]] + off]
    rim = np.concatenate([np.arange(nv), np.arange(nv - 1, nx * nv, nv)[1:],
                          np.arange(nx * nv - 1, (nx - 1) * nv - 1, -1)[1:],
                          np.arange((nx - 1) * nv, 0, -nv)[1:]])
    r0, r1 = rim, np.roll(rim, -1)
    faces += [np.stack([r0, r1, r1 + off], -1), np.stack([r0, r1 + off, r0 + off], -1)]
    mesh = trimesh.Trimesh(np.concatenate([lower, upper]), np.concatenate(faces), process=True)
    mesh.fix_normals()
    return mesh


def _write_atomic(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=path.suffix)
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_outputs(out: Path, mesh: TetMesh | None, jaw, palate) -> dict:
    """Write the tongue (unless ``mesh`` is None) with its landmarks, and the context."""
    import meshio

    from tonguevis.mesh import find_landmarks

    out.mkdir(parents=True, exist_ok=True)
    if mesh is not None:
        _write_atomic(out / "tongue.vtu", lambda p: meshio.write(
            p, meshio.Mesh(mesh.points, [("tetra", mesh.tets.astype(np.int32))]), file_format="vtu",
            binary=True, compression="zlib"))
        landmarks = find_landmarks(mesh)
        _write_atomic(out / "tongue_landmarks.json",
                      lambda p: Path(p).write_text(landmarks.to_json(mesh, mesh_file="tongue.vtu")))
    for name, surface in (("jaw.stl", jaw), ("palate.stl", palate)):
        scaled = surface.copy()
        scaled.apply_scale(MM)
        _write_atomic(out / name, lambda p, m=scaled: m.export(p, file_type="stl"))
    return {name: hashlib.sha256((out / name).read_bytes()).hexdigest()[:12]
            for name in ("tongue.vtu", "tongue_landmarks.json", "jaw.stl", "palate.stl")}


def render(folder: Path, png: Path) -> None:
    """Off-screen picture of the tongue with its landmarks and context surfaces."""
    import pyvista as pv

    from tonguevis.mesh import read_landmarks, read_mesh, read_surface

    pv.OFF_SCREEN = True
    mesh = read_mesh(folder / "tongue.vtu", unit="m")
    landmarks = read_landmarks(folder / "tongue_landmarks.json", mesh)
    mm = mesh.points * 1e3
    grid = pv.UnstructuredGrid({pv.CellType.TETRA: mesh.tets}, mm)
    surface = grid.extract_surface(algorithm="dataset_surface")

    def poly(name):
        points, triangles = read_surface(folder / name)
        return pv.PolyData(points * 1e3, np.column_stack([np.full(len(triangles), 3), triangles]).ravel())

    plotter = pv.Plotter(shape=(1, 2), window_size=(1600, 720), off_screen=True)
    for column, (view, title) in enumerate([("iso", "tongue, jaw arch and palate"), ("side", "left side (x anterior)")]):
        plotter.subplot(0, column)
        plotter.add_mesh(surface, color="#e8a0a0", show_edges=True, edge_color="#8a5050", line_width=0.5,
                         smooth_shading=False)
        plotter.add_mesh(poly("jaw.stl"), color="#f2efe4", opacity=0.45 if column == 0 else 0.2)
        plotter.add_mesh(poly("palate.stl"), color="#c9b3d9", opacity=0.35 if column == 0 else 0.2)
        sensors = np.array([mm[i] for i in landmarks.sensors.values()])
        plotter.add_points(sensors, color="#1f5fbf", point_size=16, render_points_as_spheres=True)
        plotter.add_point_labels(sensors, list(landmarks.sensors), font_size=14, point_size=1,
                                 shape_opacity=0.6, always_visible=True)
        plotter.add_points(mm[landmarks.anchors], color="#2a9d2a", point_size=16, render_points_as_spheres=True)
        plotter.add_text(f"{title}\n{mesh.n_nodes} nodes, {mesh.n_tets} tets, {mesh.volume * 1e6:.1f} cm3; "
                         "blue: sensors, green: anchors", font_size=10)
        if view == "iso":
            plotter.camera_position = [(60.0, 130.0, 120.0), (-38.0, 0.0, 28.0), (0.0, 0.0, 1.0)]
        else:
            plotter.view_vector((0.0, 1.0, 0.0), viewup=(0.0, 0.0, 1.0))
            plotter.camera.zoom(1.3)
    png.parent.mkdir(parents=True, exist_ok=True)
    plotter.screenshot(str(png))
    plotter.close()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "meshes")
    parser.add_argument("--render", type=Path, default=REPO / "docs" / "images" / "tongue_mesh.png")
    parser.add_argument("--no-render", action="store_true")
    parser.add_argument("--context-only", action="store_true",
                        help="rewrite jaw/palate (and the rendering) but keep the existing tongue and landmarks")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")

    if args.context_only:
        hashes = write_outputs(args.out, None, jaw_surface(), palate_surface())
        if not args.no_render:
            render(args.out, args.render)
        print(hashes)
        return 0
    surface = tongue_surface()
    print(f"surface: {len(surface.vertices)} vertices, {surface.volume / 1e3:.1f} cm3, "
          f"extent {np.ptp(surface.vertices, axis=0).round(1)} mm")
    mesh = tetrahedralise(surface)
    quality = tet_quality(mesh.points, mesh.tets)
    print(f"tet mesh: {mesh.n_nodes} nodes, {mesh.n_tets} tets, {mesh.volume * 1e6:.1f} cm3, "
          f"min volume {mesh.tet_volumes().min() * 1e9:.3g} mm3, "
          f"radius ratio min {quality.min():.3f} / 5th pct {np.percentile(quality, 5):.3f} / median "
          f"{np.median(quality):.3f}")
    hashes = write_outputs(args.out, mesh, jaw_surface(), palate_surface())
    for name, digest in hashes.items():
        print(f"  {name}: {(args.out / name).stat().st_size / 1e3:.0f} kB sha256 {digest}")
    if not args.no_render:
        render(args.out, args.render)
        print(f"rendering: {args.render}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
