"""From raw sensor motion to clean, aligned, segmented motion (§3.1-3.2).

Pure functions of a :class:`~tonguevis.io.Recording`:

* rest pose: :func:`find_rest_interval`, :func:`rest_pose`
* corrections: :func:`correct_jaw`, :func:`correct_head`
* filtering: :func:`smooth` (Savitzky-Golay, NaN-aware), :func:`derivative`
* alignment onto mesh nodes: :class:`SimilarityTransform`, :func:`fit_similarity`,
  :func:`align_paper`
* temporal segmentation: :func:`find_trains`, :func:`find_productions`
  -> :class:`ProductionTable` of :class:`Production`
"""

from tonguevis.preprocess.alignment import SimilarityTransform, align_paper, fit_similarity
from tonguevis.preprocess.correction import correct_head, correct_jaw
from tonguevis.preprocess.filtering import derivative, smooth
from tonguevis.preprocess.productions import Production, ProductionTable, find_productions
from tonguevis.preprocess.rest import find_rest_interval, rest_pose
from tonguevis.preprocess.trains import find_trains

__all__ = [
    "Production", "ProductionTable", "SimilarityTransform", "align_paper", "correct_head",
    "correct_jaw", "derivative", "find_productions", "find_rest_interval", "find_trains",
    "fit_similarity", "rest_pose", "smooth",
]
