"""Off-screen rendering of a :class:`~tonguevis.analysis.morph.Morph` to PNG or MP4 (pyvista, no Qt).

The elements are coloured by the CDF of their source–target difference
(eq. 14): blue where the two shapes agree, red where they differ most, with
the colours spread evenly over the mesh.  A PNG is a strip of snapshots from
source (t = 0) to target (t = 1), like Fig. 15; an MP4 plays the morph forward
and back with one large oblique view and the three small orthogonal views
(top, front, lateral) following.  MP4 frames are piped to ffmpeg by
imageio-ffmpeg.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tonguevis._files import atomic_write
from tonguevis.analysis.morph import Morph, play_schedule

COLORMAP = "coolwarm"  # blue = low difference, red = high
SCALAR_BAR = "difference percentile (eq. 14, CDF)"


def scalar_bar_title(morph: Morph) -> str:
    """The colour legend's title for the morph's kind of element difference."""
    what = "eq. 14" if morph.difference == "eq14" else "mean node distance²"
    return f"difference percentile ({what}, CDF)"


def bar_args(morph: Morph) -> dict:
    """Scalar-bar settings: horizontal, at the bottom of the view, titled for the morph."""
    return {**_BAR_ARGS, "title": scalar_bar_title(morph)}

#: Camera directions (from the focal point towards the camera) and up vectors, our frame
#: (x anterior, y left, z up).
_BAR_ARGS = {"title": SCALAR_BAR, "vertical": False, "fmt": "%.2f", "position_x": 0.15, "position_y": 0.03,
             "width": 0.7, "height": 0.07, "title_font_size": 12, "label_font_size": 11, "n_labels": 5}
VIEWS = {
    "oblique": ((0.9, -1.2, 0.7), (0, 0, 1)),
    "top": ((0, 0, 1), (1, 0, 0)),
    "front": ((1, 0, 0), (0, 0, 1)),
    "lateral": ((0, -1, 0), (0, 0, 1)),
}


def morph_surface(morph: Morph):
    """The boundary surface of the morph's mesh at rest (PolyData) with cell data "difference"
    (the CDF colour of the tet each face belongs to) and point data "vtkOriginalPointIds" (mesh nodes)."""
    import pyvista as pv

    mesh = morph.model.mesh
    cells = np.hstack([np.full((mesh.n_tets, 1), 4), mesh.tets]).ravel()
    grid = pv.UnstructuredGrid(cells, np.full(mesh.n_tets, pv.CellType.TETRA, dtype=np.uint8),
                               mesh.points.astype(np.float64))
    grid.cell_data["difference"] = morph.element_colour
    return grid.extract_surface(pass_pointid=True, algorithm="dataset_surface")


def place_camera(plotter, view: str, centre, radius: float, zoom: float = 1.0) -> None:
    """Point the current renderer's camera at ``centre`` from the direction of ``VIEWS[view]``,
    far enough that a sphere of ``radius`` fits the viewport both ways (then ``zoom``)."""
    direction, up = VIEWS[view]
    d = np.asarray(direction, float)
    d /= np.linalg.norm(d)
    camera = plotter.camera
    width, height = plotter.renderer.GetSize()
    aspect = width / height if height else 1.0
    half_v = np.radians(camera.view_angle) / 2
    half_h = np.arctan(np.tan(half_v) * aspect)
    distance = 1.05 * radius / np.sin(min(half_v, half_h))
    camera.focal_point = tuple(centre)
    camera.position = tuple(np.asarray(centre) + distance * d)
    camera.up = up
    plotter.reset_camera_clipping_range()
    camera.zoom(zoom)


def morph_bounds(morph: Morph, ts) -> tuple[np.ndarray, float]:
    """Centre and radius covering every frame of the morph (fixed camera while it plays)."""
    pts = morph.model.mesh.points[None] + morph.displacements(ts)
    lo, hi = pts.reshape(-1, 3).min(0), pts.reshape(-1, 3).max(0)
    return 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))


def render_png(morph: Morph, path, steps=(0.0, 0.25, 0.5, 0.75, 1.0), view: str = "oblique",
               size=(1500, 460), title: str | None = None) -> Path:
    """A strip of snapshots at blend parameters ``steps`` (t = 0 source, 1 target) written as PNG."""
    import pyvista as pv

    path = Path(path)
    surface = morph_surface(morph)
    point_ids = surface.point_data["vtkOriginalPointIds"]
    disp = morph.displacements(np.asarray(steps, float))
    centre, radius = morph_bounds(morph, np.asarray(steps, float))
    plotter = pv.Plotter(off_screen=True, shape=(1, len(steps)), window_size=size, border=False)
    try:
        for k, t in enumerate(steps):
            plotter.subplot(0, k)
            shown = surface.copy()
            shown.points = morph.model.mesh.points[point_ids] + disp[k][point_ids]
            plotter.add_mesh(shown, scalars="difference", cmap=COLORMAP, clim=(0, 1), show_edges=False,
                             show_scalar_bar=(k == len(steps) // 2), scalar_bar_args=bar_args(morph))
            name = {0.0: morph.labels[0] + " (t = 0)", 1.0: morph.labels[1] + " (t = 1)"}.get(float(t), f"t = {t:.2f}")
            plotter.add_text(name, font_size=8, position="upper_edge")
            place_camera(plotter, view, centre, radius, zoom=1.3)
        if title:
            plotter.subplot(0, 0)
            plotter.add_text(title, font_size=9, position=(10, 10))
        atomic_write(path, lambda tmp: plotter.screenshot(str(tmp)))
    finally:
        plotter.close()
    return path


def render_mp4(morph: Morph, path, n_frames: int = 60, fps: int = 30, back: bool = True,
               size=(1280, 720), title: str | None = None, progress=None) -> Path:
    """Play the morph forward (and back) to an MP4: one oblique view and the top/front/lateral views."""
    import pyvista as pv

    from tonguevis._progress import report
    from tonguevis.render.mp4 import write_mp4

    path = Path(path)
    ts = play_schedule(n_frames, back=back)
    disp = morph.displacements(ts, dtype=np.float32)
    centre, radius = morph_bounds(morph, ts[: n_frames])
    surface = morph_surface(morph)
    point_ids = surface.point_data["vtkOriginalPointIds"]
    rest = morph.model.mesh.points[point_ids]
    plotter = pv.Plotter(off_screen=True, shape="1|3", window_size=size, border=False)
    shown = []
    try:
        for k, view in enumerate(("oblique", "top", "front", "lateral")):
            plotter.subplot(k)
            mesh = surface.copy()
            shown.append(mesh)
            plotter.add_mesh(mesh, scalars="difference", cmap=COLORMAP, clim=(0, 1),
                             show_scalar_bar=(k == 0), scalar_bar_args=bar_args(morph))
            plotter.add_text(view, font_size=8, position="upper_left")
            place_camera(plotter, view, centre, radius, zoom=1.3)
        plotter.subplot(0)
        label = plotter.add_text("", font_size=10, position="upper_right")
        plotter.add_text(f"{morph.labels[0]} (t = 0)  →  {morph.labels[1]} (t = 1)"
                         + (f"\n{title}" if title else ""), font_size=8, position="upper_edge")

        def pictures():
            for f, t in enumerate(ts):
                for mesh in shown:
                    mesh.points[:] = rest + disp[f][point_ids]
                label.SetText(3, f"t = {t:.2f}")
                plotter.render()
                yield plotter.screenshot(return_img=True)
                report(progress, f + 1, len(ts), "rendering the morph")

        # crf 15 with x264's default preset: the encoding imageio-ffmpeg's quality=7 made before.
        write_mp4(path, pictures(), size, fps, crf=15, preset="medium")
    finally:
        plotter.close()
    return path
