"""Deformation segmentation with rigid and constraint modes (§5 of Yang et al. 2013).

Partitions are face-connected tet sets grown in competition (Algorithm 5.1);
each is fitted by its local rigid modes (eq. 9) or constraint modes (eq. 13)
and the segmentation keeps the growth that fits best.  Entry point:
:func:`segment`; targets: :class:`SegmentationTarget` (see also
:mod:`.targets` for targets taken from a simulated :class:`Motion`)::

    target = peak_energy_target(motion, production)      # or frame_target / production_target
    result = segment(model, target, "constraint", seeds="auto", threshold=0.05,
                     progress=callback)                   # or seeds=[tet, tet, ...]
    result.labels, result.element_errors, result.approximated_points()

Errors use the volume-lumped norm (see :mod:`.target`); the "relative global
error" that autoseeding compares with its threshold (the paper's "5 percent
e_G") is ‖ũ − u‖² / ‖u‖², i.e. e_G divided by the e_G of the zero
approximation.  No Qt and no plotting here; :mod:`tonguevis.render.segmentation` draws off screen with pyvista.
"""

from tonguevis.analysis.segmentation.api import MODES, make_fitter, segment
from tonguevis.analysis.segmentation.errors import SegmentationError
from tonguevis.analysis.segmentation.graph import TetGraph
from tonguevis.analysis.segmentation.result import SegmentationResult
from tonguevis.analysis.segmentation.target import SegmentationTarget
from tonguevis.analysis.segmentation.targets import (
    frame_target,
    peak_energy_target,
    production_target,
)

__all__ = [
    "MODES",
    "SegmentationError",
    "SegmentationResult",
    "SegmentationTarget",
    "TetGraph",
    "frame_target",
    "make_fitter",
    "peak_energy_target",
    "production_target",
    "segment",
]
