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
    points, laterals, samples, registration = [], [], {}, {}
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
        laterals.append(np.concatenate(list(lateral.values())) if len(lateral) == 2 else None)
    if not frame_pose and len(points) > 1:  # no head references anywhere: the traces' own shapes register them
        motions, said = registered_by_shape(points)
        for k, (rotation, translation) in motions.items():
            points[k] = points[k] @ rotation.T + translation
            laterals[k] = None if laterals[k] is None else laterals[k] @ rotation.T + translation
        registration.update({str(paths[k]): info for k, info in said.items()})
        if motions:
            registration[str(paths[0])] = "no head references: the palate's frame, the others registered to it"
    midlines = [float(np.nanmean(v[:, 1])) for v in laterals if v is not None]
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


#: Rounds of registering each trace (but the first, the palate's frame) to the others' surface.
SHAPE_ROUNDS = 3
#: m²: the smoothing of the surface a trace is registered to (the fit's own before its fold bound).
SHAPE_SMOOTHING = 5e-5
#: m: traces that would move further than this to agree with the others are kept as recorded: they are not
#: the same palate in the same frame (another sitting's head pose far off, another speaker), said and not forced.
MAX_TRACE_MOVE = 5e-3


def registered_by_shape(points: list[np.ndarray]) -> tuple[dict, dict]:
    """({trace index: (rotation (3, 3), translation (3,))}, {trace index: what the metadata say}): the small
    rigid motions that lay each palate trace but the first (k, 3 each, metres, the first one's frame is the
    palate's) onto the surface fitted to the others where they overlap (:func:`tonguevis.palate.
    rigid_fit_to_surface`), :data:`SHAPE_ROUNDS` rounds in turn.  For traces without head references: each
    was head-corrected in its own sitting, and a palate is rigid, so where two traces cover the same place they
    must agree.  On the shared OSN12 traces the scribble lay 1-2 mm above the midsagittal trace in front
    (the joint fit then 1.5 mm off that trace there, 0.5 mm after: a 5.5 degree pitch of the scribble, a
    3 degree roll of the coronal trace).  No motions when any trace would move more than
    :data:`MAX_TRACE_MOVE` (the metadata say so)."""
    from tonguevis.palate import GRID_STEP, _fit_palate, rigid_fit_to_surface, symmetry_midline

    moved = [np.asarray(p, dtype=np.float64) for p in points]
    total = {k: (np.eye(3), np.zeros(3)) for k in range(1, len(moved))}
    first, last = {}, {}
    for _ in range(SHAPE_ROUNDS):
        for k in range(1, len(moved)):
            others = np.concatenate([p for j, p in enumerate(moved) if j != k])
            if len(others) < 20:
                continue
            midline = symmetry_midline(np.concatenate(moved))
            found = rigid_fit_to_surface(moved[k], _fit_palate(others, midline, SHAPE_SMOOTHING, GRID_STEP, None),
                                         others)
            if found is None:
                continue
            rotation, translation, last[k] = found
            first.setdefault(k, last[k]["rms_before_mm"])
            moved[k] = moved[k] @ rotation.T + translation
            r0, t0 = total[k]
            total[k] = (rotation @ r0, rotation @ t0 + translation)
    motions = {k: total[k] for k in last}
    said = {}
    for k, (rotation, translation) in motions.items():
        pts = np.asarray(points[k], dtype=np.float64)
        move = float(np.max(np.linalg.norm(pts @ rotation.T + translation - pts, axis=1)))
        angle = float(np.degrees(np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1, 1))))
        said[k] = {"by": "registered to the other traces by its shape (no head references)", "largest_move_mm": round(1e3 * move, 2),
                   "turn_deg": round(angle, 2), "rms_to_the_others_mm": [round(first[k], 3),
                                                                         round(last[k]["rms_after_mm"], 3)]}
    if any(info["largest_move_mm"] > 1e3 * MAX_TRACE_MOVE for info in said.values()):
        return {}, {k: {**info, "by": "not registered: the traces disagree by more than "
                                     f"{1e3 * MAX_TRACE_MOVE:.0f} mm (taken as recorded)"} for k, info in said.items()}
    return motions, said
