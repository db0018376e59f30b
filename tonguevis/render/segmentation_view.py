"""Drawing data of the Segmentation tab, without Qt: surfaces, colours, the partition table.

The target surface is the boundary of the tet mesh at the target shape; the
approximation surface is the boundary of the *split* mesh (every partition has
its own node copies) at the approximated shape, so rigid pieces show their
gaps and overlaps, while constraint modes, which keep the target on interface
nodes, close them.  Both carry per-face ``colour`` (partition, the palette of
:mod:`tonguevis.render.segmentation`), ``partition`` and
``error_mm`` (sqrt of the tet's e_E, mm) taken from the tet behind the face,
and ``tet`` (that tet's id), which is how a clicked face becomes a seed.
"""

from __future__ import annotations

import numpy as np

from tonguevis.render.segmentation import _grid, _partition_colours
from tonguevis.errors import TonguevisError

ERROR_FIELD = "error_mm"
ERROR_TITLE = "local error sqrt(e_E), mm"
#: Direction from the tongue to the camera: its right side, a little in front and above.
VIEW = (0.45, -1.0, 0.5)
REST_COLOUR = "#c8b4a0"
#: Targets the tab offers: key -> label.
TARGETS = {"frame": "current frame", "peak": "peak-energy frame of the production under the cursor",
           "production": "whole production under the cursor (energy-weighted)"}


def production_at(productions, time: float) -> tuple[float, float] | None:
    """The (start_s, end_s) production containing ``time``, else None."""
    for start, end in productions or []:
        if start <= time <= end:
            return float(start), float(end)
    return None


def make_target(kind: str, motion, productions, time: float):
    """The SegmentationTarget of ``kind`` (a key of :data:`TARGETS`) at cursor ``time`` (s)."""
    from tonguevis.analysis.segmentation.targets import frame_target, peak_energy_target, production_target

    if motion is None:
        raise TonguevisError("no simulated motion yet: open a recording and let it simulate first")
    if kind == "frame":
        return frame_target(motion, time=time)
    if kind not in TARGETS:
        raise TonguevisError(f"unknown segmentation target {kind!r}")
    production = production_at(productions, time)
    if production is None:
        raise TonguevisError(f"no production under the cursor at {time:.2f} s: move the cursor into a "
                             "production (the shaded spans of the time line) or segment the current frame")
    return peak_energy_target(motion, production) if kind == "peak" else production_target(motion, production)


def _surface(points: np.ndarray, tets: np.ndarray, result):
    surface = frame_surface(points, tets)
    tet = np.asarray(surface.cell_data["tet"], dtype=np.int64)
    surface.cell_data["partition"] = result.labels[tet]
    surface.cell_data["colour"] = _partition_colours(result.labels)[tet]
    surface.cell_data[ERROR_FIELD] = 1000.0 * np.sqrt(result.element_errors[tet])
    return surface


def frame_surface(points: np.ndarray, tets: np.ndarray):
    """pyvista PolyData: the boundary of a tet mesh at ``points`` with per-face ``tet`` (for picking)."""
    grid = _grid(points, tets)
    grid.cell_data["tet"] = np.arange(len(tets), dtype=np.int64)
    return grid.extract_surface(pass_pointid=True, pass_cellid=False, algorithm="dataset_surface")


def target_surface(result, frame: int | None = None, scale: float = 1.0):
    """pyvista PolyData: the target shape's boundary (peak frame by default), coloured per face.

    scale : factor on the displacement (1 = true shape; more makes small gaps visible)."""
    frame = result.peak_frame if frame is None else int(frame)
    return _surface(result.points + scale * result.target[frame], result.tets, result)


def approximation_surface(result, frame: int | None = None, scale: float = 1.0):
    """pyvista PolyData: the approximated shape on the split mesh (its point ``node`` = mesh node)."""
    frame = result.peak_frame if frame is None else int(frame)
    points = result.points[result.split_nodes] + scale * result.approximation[frame]
    surface = _surface(points, result.split_tets, result)
    # Which mesh node each drawn point is a copy of (interfaces can be checked against the target).
    surface.point_data["node"] = result.split_nodes[np.asarray(surface.point_data["vtkOriginalPointIds"])]
    return surface


def partition_table(result) -> str:
    """A monospaced table: one line per partition (tets, volume, rms error) and the global error."""
    lines = [f"{'part':>4} {'tets':>5} {'cm³':>7} {'rms mm':>7} {'seed':>5}"]
    for row in result.partition_rows():
        lines.append(f"{row['partition']:>4} {row['tets']:>5} {row['volume_cm3']:>7.2f} "
                     f"{row['rms_error_mm']:>7.3f} {row['seed']:>5}")
    lines.append(f"{result.mode} modes, {result.n_partitions} partitions")
    lines.append(f"relative e_G {100 * result.relative_error:.2f} %")
    return "\n".join(lines)


# ---------------------------------------------------------------- drawing (a pyvista plotter of shape (1, 2))
def _place_camera(plotter) -> None:
    plotter.subplot(0, 0)
    plotter.view_vector(VIEW, viewup=(0.0, 0.0, 1.0))
    plotter.reset_camera()
    plotter.camera.zoom(1.25)


def draw_result(plotter, result, by_error: bool = False, scale: float = 1.0) -> dict:
    """Target (left, by partition) and approximation (right, by partition or local error).

    Returns {"target", "approximation"} surfaces and their ``*_actor``s; the views are
    expected linked, so one camera serves both.
    """
    top = float(1000.0 * np.sqrt(result.element_errors.max())) or 1.0
    shown = "" if scale == 1 else f", displacement ×{scale:g}"
    panels = [("target", target_surface(result, scale=scale),
               f"target{shown}, jaw frame\n{result.metadata.get('description', '')}"),
              ("approximation", approximation_surface(result, scale=scale),
               f"approximation, {result.mode} modes\nrelative e_G {100 * result.relative_error:.2g} %")]
    drawn = {}
    for column, (name, surface, caption) in enumerate(panels):
        plotter.subplot(0, column)
        if by_error and name == "approximation":
            actor = plotter.add_mesh(surface, scalars=ERROR_FIELD, cmap="viridis", clim=(0.0, top),
                                     scalar_bar_args={"title": ERROR_TITLE, "color": "black", "vertical": False,
                                                      "position_x": 0.2, "position_y": 0.06, "width": 0.6, "title_font_size": 12,
                                                      "label_font_size": 12, "fmt": "%.2f"})
        else:
            actor = plotter.add_mesh(surface, scalars="colour", rgb=True, lighting=True)
        plotter.add_text(caption, font_size=9, color="black", position="upper_left")
        drawn[name], drawn[f"{name}_actor"] = surface, actor
    _place_camera(plotter)
    return drawn


def frame_caption(time: float) -> str:
    return f"frame at {time:.3f} s, jaw frame (not segmented yet)"


def draw_frame(plotter, points: np.ndarray, tets: np.ndarray, time: float) -> dict:
    """Before any result: one frame's shape on the left (pickable), plain colour."""
    surface = frame_surface(points, tets)
    plotter.subplot(0, 0)
    actor = plotter.add_mesh(surface, color=REST_COLOUR, lighting=True)
    plotter.add_text(frame_caption(time), font_size=9, color="black", position="upper_left", name="frame caption")
    _place_camera(plotter)
    return {"target": surface, "target_actor": actor}


def move_frame(plotter, surface, points: np.ndarray, time: float) -> None:
    """Move the drawn frame to new (n, 3) mesh points in place and re-caption it."""
    surface.points = np.asarray(points)[np.asarray(surface.point_data["vtkOriginalPointIds"])]
    plotter.subplot(0, 0)
    plotter.add_text(frame_caption(time), font_size=9, color="black", position="upper_left", name="frame caption")


def draw_seed_markers(plotter, centres: np.ndarray, groups: dict) -> None:
    """Dots in the left view at tet centres ``centres`` (k, 3): ``groups`` = name -> (tets, colour)."""
    plotter.subplot(0, 0)
    for name, (tets, colour) in groups.items():
        tets = np.asarray(tets, dtype=np.int64)
        if len(tets) == 0 or tets.max() >= len(centres):
            plotter.remove_actor(name, render=False)
            continue
        plotter.add_points(centres[tets], color=colour, point_size=9, render_points_as_spheres=True,
                           name=name, reset_camera=False, pickable=False)
