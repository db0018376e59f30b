"""From raw sensor motion to clean, aligned, segmented motion (§3.1-3.2).

Pure functions of a :class:`~tonguevis.io.Recording`:

* rest pose: :func:`choose_rest_interval` -> :class:`RestChoice` (given, detected
  by :func:`find_rest_interval`, or :func:`stillest_window`), :func:`rest_pose`
* corrections: :func:`correct_jaw`, :func:`correct_head`, :func:`head_corrected`
* filtering: :func:`smooth` (Savitzky-Golay, NaN-aware), :func:`derivative`
* alignment onto mesh nodes: :class:`SimilarityTransform`, :func:`fit_similarity`,
  :func:`align_paper`
* temporal segmentation: :func:`find_trains`, :func:`find_productions`
  -> :class:`ProductionTable` of :class:`Production`
* targets for a model: :func:`prepare_targets` -> :class:`PreparedTargets`
"""

from tonguevis.preprocess.alignment import SimilarityTransform, align_paper, fit_similarity
from tonguevis.preprocess.correction import correct_head, correct_jaw, head_corrected, head_references
from tonguevis.preprocess.filtering import derivative, smooth
from tonguevis.preprocess.productions import Production, ProductionTable, find_productions
from tonguevis.preprocess.rest import (
    RestChoice, check_rest_interval, choose_rest_interval, find_rest_interval, rest_pose, stillest_window,
)
from tonguevis.preprocess.targets import PreparedTargets, prepare_targets
from tonguevis.preprocess.trains import find_trains

__all__ = [
    "PreparedTargets", "Production", "ProductionTable", "RestChoice", "SimilarityTransform", "align_paper",
    "check_rest_interval", "choose_rest_interval", "correct_head", "correct_jaw", "derivative",
    "find_productions", "find_rest_interval", "find_trains", "fit_similarity", "head_corrected", "head_references",
    "prepare_targets", "rest_pose", "smooth", "stillest_window",
]
