"""The two frames of reference a motion can be shown in (DESIGN.md, "Conventions").

The tongue is simulated in the **jaw frame**: the jaw's motion removed, its
anchors riding on the jaw.  That is where deformation lives (energy,
segmentation, morphing).  People look at it in the **head frame**: the tongue
and the jaw carried by the jaw's motion, the palate fixed to the head.  A
:class:`~tonguevis.sim.Motion` carries the jaw's translation from rest,
``motion.jaw_offset`` (F, 3) metres in the model frame: a node at ``p`` in the
jaw frame is at ``p + jaw_offset[i]`` in the head frame, and the head-fixed
palate is at ``palate - jaw_offset[i]`` in the jaw frame.
"""

from __future__ import annotations

import numpy as np

#: "head": the tongue and jaw move with the jaw, the palate is fixed; "jaw": the jaw's motion removed.
REFERENCE_FRAMES = ("head", "jaw")


def check_reference(frame: str) -> str:
    """``frame`` if it is one of :data:`REFERENCE_FRAMES`, else ValueError naming them."""
    if frame not in REFERENCE_FRAMES:
        raise ValueError(f"unknown frame of reference {frame!r}; choose one of {', '.join(REFERENCE_FRAMES)}")
    return frame


#: A jaw that never moves further than this from rest (m) did not move (rounding of the corrections).
STILL_JAW = 1e-6


def jaw_moves(motion) -> bool:
    """True when the motion has a jaw offset beyond rounding (a jaw sensor was recorded and moved)."""
    offset = getattr(motion, "jaw_offset", None)
    return offset is not None and len(offset) > 0 and bool(np.nanmax(np.abs(offset)) > STILL_JAW)


def tongue_offset(motion, frame: str) -> np.ndarray:
    """(F, 3) metres added to the jaw-frame tongue (and jaw) to draw it in ``frame``: the jaw offset or zeros."""
    check_reference(frame)
    if frame == "head" and jaw_moves(motion):
        return np.asarray(motion.jaw_offset, dtype=np.float64)
    return np.zeros((len(motion.times), 3))


def describe(frame: str, moves: bool = True) -> str:
    """A one-line caption of ``frame`` (``moves``: whether the motion's jaw moved at all)."""
    check_reference(frame)
    if not moves:
        return "head frame = jaw frame (no jaw motion recorded)"
    if frame == "head":
        return "head frame: tongue and jaw move with the jaw, palate fixed"
    return "jaw frame: the jaw's motion removed (the palate moves)"


def export_note(frame: str, moves: bool, motion=None) -> str:
    """What a VTK series folder's README says about the frame its points are in and their point data."""
    check_reference(frame)
    lines = [f"Frame of reference: {describe(frame, moves)}.", ""]
    if not moves:
        lines.append("The recording has no jaw motion (no jaw sensor, or it did not move): the points are the "
                     "simulated tongue, which is the same in the head and the jaw frame.")
    elif frame == "head":
        lines += ["The points are the tongue in the head frame: the simulated shape (jaw frame) plus the jaw's",
                  "translation from rest (jaw_offset.csv, per frame). Point data:",
                  "displacement = head-frame position minus rest position (metres);",
                  "deformation = the tongue's own deformation (jaw frame), what the elastic energy measures.",
                  "Export with --frame jaw (or in the app's jaw frame) for the points without the jaw's motion."]
    else:
        lines += ["The points are the tongue in the jaw frame (the jaw's translation removed), where it is",
                  "simulated: displacement = deformation = the tongue's own deformation (metres).",
                  "Add the jaw's translation (jaw_offset.csv, per frame) to place it in the head frame."]
    from tonguevis.sim.placement import frame_words

    lines += ["", f"Units: metres, seconds; axes x anterior, y left, z up ({frame_words(motion)})."]
    return "\n".join(lines) + "\n"


def write_export_notes(folder, motion, frame: str) -> None:
    """README.txt (which frame, which fields) and jaw_offset.csv (time_s, x_m, y_m, z_m per frame) in ``folder``."""
    from pathlib import Path

    from tonguevis._files import atomic_write_text

    folder = Path(folder)
    atomic_write_text(folder / "README.txt", export_note(frame, jaw_moves(motion), motion))
    times = np.asarray(motion.times, dtype=np.float64)
    jaw = np.zeros((len(times), 3)) if motion.jaw_offset is None else np.asarray(motion.jaw_offset, dtype=np.float64)
    rows = "".join(f"{t:.6f},{x:.9g},{y:.9g},{z:.9g}\n" for t, (x, y, z) in zip(times, jaw))
    atomic_write_text(folder / "jaw_offset.csv", "time_s,x_m,y_m,z_m\n" + rows)
