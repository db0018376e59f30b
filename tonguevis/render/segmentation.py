"""Off-screen pictures of segmentations (pyvista, no Qt): target | approximation | error.

One row per result: the target shape coloured by partition, the approximated
shape (on the split mesh, so rigid pieces show their gaps) coloured by
partition, and the local error sqrt(e_E) in mm on the target shape, on one
colour scale for all rows.  The camera looks at the right side of the tongue
from slightly in front and above (x anterior to the right of the picture, z
up); ``view=(0, -1, 0)`` gives the pure side view (the bar's bending plane).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import numpy as np

from tonguevis.analysis.segmentation.result import SegmentationResult

#: Direction from the shape to the camera: right side (−y), a little in front (+x) and above (+z).
OBLIQUE = (0.45, -1.0, 0.5)

PALETTE = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
           "#bcbd22", "#17becf", "#aec7e8", "#ffbb78", "#98df8a", "#ff9896", "#c5b0d5", "#c49c94"]


def _grid(points: np.ndarray, tets: np.ndarray):
    import pyvista as pv

    cells = np.hstack([np.full((len(tets), 1), 4), tets]).ravel()
    types = np.full(len(tets), pv.CellType.TETRA, dtype=np.uint8)
    return pv.UnstructuredGrid(cells, types, np.asarray(points, dtype=np.float64))


def _partition_colours(labels: np.ndarray) -> np.ndarray:
    from matplotlib.colors import to_rgb

    table = np.array([to_rgb(PALETTE[i % len(PALETTE)]) for i in range(int(labels.max()) + 1)])
    return (255 * table[labels]).astype(np.uint8)


def render_png(results: SegmentationResult | Sequence[SegmentationResult], path: str | os.PathLike,
               titles: Sequence[str] | None = None, frame: int | None = None,
               panel_size: tuple[int, int] = (520, 400), exaggeration: float = 1.0,
               view: tuple[float, float, float] = OBLIQUE) -> Path:
    """Write a PNG with one row (target | approximation | error) per result.

    frame : target frame to show (default: each result's peak frame).
    exaggeration : factor on the displacements (1 = true scale).
    """
    import pyvista as pv

    if isinstance(results, SegmentationResult):
        results = [results]
    rows = len(results)
    top = max(1000.0 * float(np.sqrt(r.element_errors.max())) for r in results) or 1.0
    plotter = pv.Plotter(off_screen=True, shape=(rows, 3), window_size=(3 * panel_size[0], rows * panel_size[1]),
                         border=False)
    plotter.set_background("white")
    for row, result in enumerate(results):
        shown = result.peak_frame if frame is None else int(frame)
        target = result.target[shown]
        colours = _partition_colours(result.labels)
        title = titles[row] if titles is not None else ""
        summary = (f"{result.mode} modes, {result.n_partitions} partitions, "
                   f"relative e_G {100 * result.relative_error:.2g} %")
        deformed = _grid(result.points + exaggeration * target, result.tets)
        deformed.cell_data["colour"] = colours
        approx = _grid(result.points[result.split_nodes] + exaggeration * result.approximation[shown],
                       result.split_tets)
        approx.cell_data["colour"] = colours
        errors = _grid(result.points + exaggeration * target, result.tets)
        errors.cell_data["local error (mm, rms)"] = 1000.0 * np.sqrt(result.element_errors)
        panels = [
            (deformed, "colour", f"{title}\ntarget, coloured by partition".strip()),
            (approx, "colour", f"approximation\n{summary}"),
            (errors, "local error (mm, rms)", "local error sqrt(e_E)"),
        ]
        for column, (grid, scalars, caption) in enumerate(panels):
            plotter.subplot(row, column)
            if scalars == "colour":
                plotter.add_mesh(grid, scalars=scalars, rgb=True, show_edges=False, lighting=True)
            else:
                plotter.add_mesh(grid, scalars=scalars, cmap="viridis", show_edges=False, clim=(0.0, top),
                                 scalar_bar_args={"title": scalars, "color": "black", "vertical": False,
                                                  "width": 0.6, "position_x": 0.2, "position_y": 0.04})
            plotter.add_text(caption, font_size=9, color="black", position="upper_left")
            plotter.view_vector(view, viewup=(0.0, 0.0, 1.0))
            plotter.camera.zoom(1.2)
    return _write(plotter, Path(path))


def render_grid(results: Sequence[SegmentationResult], path: str | os.PathLike, titles: Sequence[str],
                columns: int = 4, panel_size: tuple[int, int] = (420, 320),
                view: tuple[float, float, float] = OBLIQUE) -> Path:
    """Write a PNG with one panel per result: its peak target shape coloured by partition
    (the Fig. 18 layout: a row per speaker, a column per syllable)."""
    import pyvista as pv

    rows = -(-len(results) // columns)
    plotter = pv.Plotter(off_screen=True, shape=(rows, columns),
                         window_size=(columns * panel_size[0], rows * panel_size[1]), border=False)
    plotter.set_background("white")
    for index, (result, title) in enumerate(zip(results, titles)):
        plotter.subplot(index // columns, index % columns)
        grid = _grid(result.points + result.target[result.peak_frame], result.tets)
        grid.cell_data["colour"] = _partition_colours(result.labels)
        plotter.add_mesh(grid, scalars="colour", rgb=True, lighting=True)
        plotter.add_text(f"{title}: {result.n_partitions} partitions, e_G {100 * result.relative_error:.2g} %",
                         font_size=9, color="black", position="upper_left")
        plotter.view_vector(view, viewup=(0.0, 0.0, 1.0))
        plotter.camera.zoom(1.3)
    return _write(plotter, Path(path))


def _write(plotter, path: Path) -> Path:
    """Save the plotter's picture as a PNG at ``path`` (a temporary file, then a rename) and close it."""
    from tonguevis._files import atomic_write

    try:
        atomic_write(path, lambda tmp: plotter.screenshot(str(tmp)))
    finally:
        plotter.close()
    return path
