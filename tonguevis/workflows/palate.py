"""The speaker's palate from palate-trace recordings, as ``tonguevis palate`` and the app fit it.

Reading recordings is a workflow step; the palate's geometry (fitting, joining, the
height field) is :mod:`tonguevis.palate`, which imports nothing of this package
(it used to, to read the traces: a cycle palate -> workflows -> sim -> palate).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tonguevis._progress import report
from tonguevis.palate import PalateError, PalateSurface, fit_palate, midline_of, trace_points

__all__ = ["palate_from_traces"]


def palate_from_traces(paths, probe: str = "PROBE", sensor_map=None, progress=None,
                       read_options: dict | None = None) -> PalateSurface:
    """The speaker's palate fitted to palate-trace recordings (``tonguevis palate`` and the app's
    File > Fit palate from traces): each read (with the reader's ``read_options``, ``-O``),
    its probe's positions head-corrected (:func:`~tonguevis.palate.trace_points`), the midline taken from the
    lateral tongue sensors when the traces have them, one surface fitted to all points
    (:func:`~tonguevis.palate.fit_palate`).  The probe's sample count per file is in ``metadata["samples"]``.
    """
    from tonguevis.workflows import open_recording  # the package's: one door for reading, scripts may wrap it

    paths = list(paths)
    if not paths:
        raise PalateError("no palate-trace recordings given")
    points, midlines, samples = [], [], {}
    for k, path in enumerate(paths):
        report(progress, k, len(paths) + 1, f"reading {Path(path).name}")
        rec = open_recording(path, sensor_map, **{**(read_options or {}), "audio": False})  # traces: no sound needed
        pts = trace_points(rec, probe)
        points.append(pts)
        samples[str(path)] = int(len(pts))
        midline = midline_of(rec)
        if midline is not None:
            midlines.append(midline)
    report(progress, len(paths), len(paths) + 1, "fitting the palate")
    surface = fit_palate(np.concatenate(points), midline_y=float(np.mean(midlines)) if midlines else None,
                         sources=[str(p) for p in paths])
    surface.metadata["samples"] = samples
    report(progress, len(paths) + 1, len(paths) + 1, "palate fitted")
    return surface
