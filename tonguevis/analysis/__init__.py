"""Analyses of simulated tongue motions (no Qt).

Segmentation (§5): :func:`segment` and its containers.  Other analyses (energy
curves, morphing, validation) live in sibling modules and add their names here.
"""

from tonguevis.analysis.segmentation import (
    SegmentationError,
    SegmentationResult,
    SegmentationTarget,
    frame_target,
    peak_energy_target,
    production_target,
    segment,
)

__all__ = [
    "SegmentationError",
    "SegmentationResult",
    "SegmentationTarget",
    "frame_target",
    "peak_energy_target",
    "production_target",
    "segment",
]
