"""The speaker's palate from palate-trace recordings, as ``tonguevis palate`` and the app fit it.

Reading recordings is a workflow step; the palate's geometry (fitting, joining, the
height field) is :mod:`tonguevis.palate`, which imports nothing of this package
(it used to, to read the traces: a cycle palate -> workflows -> sim -> palate).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tonguevis._progress import report
from tonguevis.palate import PalateError, PalateSurface, fit_palate, symmetry_midline, trace_points
from tonguevis.preprocess.correction import head_corrected, reference_pose, register_references

__all__ = ["palate_from_traces"]


def palate_from_traces(paths, probe: str = "PROBE", sensor_map=None, progress=None,
                       read_options: dict | None = None) -> PalateSurface:
    """The speaker's palate fitted to palate-trace recordings (``tonguevis palate`` and the app's
    File > Fit palate from traces): each read (with the reader's ``read_options``, ``-O``),
    its probe's positions head-corrected (:func:`~tonguevis.palate.trace_points`), the midline from the
    traces' own mirror symmetry (:func:`~tonguevis.palate.symmetry_midline`; the lateral tongue sensors
    when one side only was traced), one surface fitted to all points
    (:func:`~tonguevis.palate.fit_palate`).  The probe's sample count per file is in ``metadata["samples"]``.

    Traces with head references (>= 3 REF* sensors) are carried into the first one's head frame by
    them (the residual per file, mm, in ``metadata["trace_registration_mm"]``), and the references'
    positions are kept in ``metadata["head_references"]``: the simulation then registers the palate
    into the speech's head frame by the same references instead of guessing a shift.
    """
    from tonguevis.workflows.recording import open_recording

    paths = list(paths)
    if not paths:
        raise PalateError("no palate-trace recordings given")
    points, midlines, samples, registration = [], [], {}, {}
    frame_pose: dict = {}  # the head references of the first trace that has them: the palate's head frame
    for k, path in enumerate(paths):
        report(progress, k, len(paths) + 1, f"reading {Path(path).name}")
        rec = open_recording(path, sensor_map, **{**(read_options or {}), "audio": False})  # traces: no sound needed
        corrected = head_corrected(rec)
        pts = trace_points(corrected, probe)
        lateral = {n: corrected.sensors[n] for n in ("TL", "TR") if n in corrected.sensors}
        pose = reference_pose(corrected)
        if pose and not frame_pose:
            frame_pose = pose
        elif pose:  # another sitting: carried into the first one's head frame by the references
            rotation, translation, residual, _ = register_references(pose, frame_pose) or (None, None, None, None)
            if rotation is not None:
                pts = pts @ rotation.T + translation
                lateral = {n: v @ rotation.T + translation for n, v in lateral.items()}
                registration[str(path)] = round(1e3 * residual, 3)
        if not pose and len(paths) > 1:
            registration[str(path)] = "no head references: taken as recorded"
        points.append(pts)
        samples[str(path)] = int(len(pts))
        if len(lateral) == 2:
            midlines.append(float(np.nanmean(np.concatenate(list(lateral.values()))[:, 1])))
    report(progress, len(paths), len(paths) + 1, "fitting the palate")
    # The palate's own mirror symmetry gives the midline; the lateral tongue sensors (pushed aside by the
    # probe while tracing) only when the traces cannot tell (one side traced).
    everything = np.concatenate(points)
    midline, how = symmetry_midline(everything), "the traces' mirror symmetry"
    if midline is None and midlines:
        midline, how = float(np.mean(midlines)), "the lateral tongue sensors (the traces' symmetry could not tell)"
    surface = fit_palate(everything, midline_y=midline, sources=[str(p) for p in paths])
    if midline is not None:
        surface.metadata["midline_from"] = how
    surface.metadata["samples"] = samples
    if frame_pose:
        # Where the head references sat: the simulation carries the palate into the speech's head frame by them.
        surface.metadata["head_references"] = {n: [float(v) for v in xyz] for n, xyz in frame_pose.items()}
    if registration:
        surface.metadata["trace_registration_mm"] = registration
    report(progress, len(paths) + 1, len(paths) + 1, "palate fitted")
    return surface
