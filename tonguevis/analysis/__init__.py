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

# Energy curves, the corpus, MDS and morphing (§6.3-6.4).
from tonguevis.analysis.corpus import Corpus, CorpusEntry, load_corpus  # noqa: E402
from tonguevis.analysis.energy import EnergyCurve, GroupSummary, modal_energy, production_curves, summarize  # noqa: E402
from tonguevis.analysis.mds import MDSResult, smacof  # noqa: E402
from tonguevis.analysis.morph import Morph, cdf_colour, morph_between  # noqa: E402

__all__ += [
    "Corpus", "CorpusEntry", "EnergyCurve", "GroupSummary", "MDSResult", "Morph", "cdf_colour",
    "load_corpus", "modal_energy", "morph_between", "production_curves", "smacof",
    "summarize",
]

# Leave-one-sensor-out validation against baselines.
from tonguevis.analysis.validation import HeldOutSensor, ValidationResult, validate  # noqa: E402

__all__ += ["HeldOutSensor", "ValidationResult", "validate"]
