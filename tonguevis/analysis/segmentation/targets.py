"""Segmentation targets taken from a simulated :class:`~tonguevis.sim.motion.Motion`.

A target is the displacement of the current frame, of the frame of peak
elastic energy within a production (the Fig. 17 setting), or of a whole
production weighted by energy (eq. 5, the Fig. 18 setting).  A production is
anything with ``start`` and ``end`` in seconds (a
:class:`~tonguevis.preprocess.productions.Production`) or a (start, end) pair.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tonguevis.analysis.segmentation.errors import SegmentationError
from tonguevis.analysis.segmentation.target import SegmentationTarget


def _span(motion: Any, production: Any) -> np.ndarray:
    """Frame indices of ``motion`` inside a production (all frames when None)."""
    times = np.asarray(motion.times)
    if production is None:
        return np.arange(len(times))
    if hasattr(production, "start") and hasattr(production, "end"):
        start, end = float(production.start), float(production.end)
    else:
        try:
            start, end = (float(v) for v in production)
        except (TypeError, ValueError) as exc:
            raise SegmentationError(f"a production is a (start, end) pair in seconds, got {production!r}") from exc
    frames = np.flatnonzero((times >= start) & (times <= end))
    if len(frames) == 0:
        raise SegmentationError(
            f"no simulated frame between {start:.3f} s and {end:.3f} s (motion covers "
            f"{times[0]:.3f}-{times[-1]:.3f} s)")
    return frames


def frame_target(motion: Any, frame: int | None = None, time: float | None = None) -> SegmentationTarget:
    """The displacement of one frame (by index, or nearest to ``time`` in seconds)."""
    if (frame is None) == (time is None):
        raise SegmentationError("give either a frame index or a time")
    if frame is None:
        frame = motion.frame_at(float(time))
    frame = int(frame)
    if not 0 <= frame < motion.n_frames:
        raise SegmentationError(f"frame {frame} outside the motion's {motion.n_frames} frames")
    t = float(motion.times[frame])
    return SegmentationTarget.frame(motion.displacement(frame), t, f"frame at {t:.3f} s")


def peak_energy_target(motion: Any, production: Any = None) -> SegmentationTarget:
    """The frame of largest elastic energy (of a production, or of the whole motion)."""
    frames = _span(motion, production)
    frame = int(frames[np.argmax(np.asarray(motion.energy)[frames])])
    target = frame_target(motion, frame=frame)
    target.description = f"peak-energy frame at {motion.times[frame]:.3f} s"
    return target


def production_target(motion: Any, production: Any = None) -> SegmentationTarget:
    """All frames of a production, weighted by their elastic energy (eq. 5)."""
    frames = _span(motion, production)
    times = np.asarray(motion.times)[frames]
    return SegmentationTarget.sequence(
        motion.displacements(frames), np.asarray(motion.energy)[frames], times,
        f"production {times[0]:.3f}-{times[-1]:.3f} s ({len(frames)} frames, energy-weighted)")
