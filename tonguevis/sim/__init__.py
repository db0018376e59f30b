"""The physics: FEM assembly, modal basis, modal warping and constrained Newmark integration."""

from tonguevis.sim.material import Material
from tonguevis.sim.modal import ModalBasis
from tonguevis.sim.model import TongueModel
from tonguevis.sim.motion import Motion
from tonguevis.sim.simulate import prepare_targets, simulate

__all__ = ["Material", "ModalBasis", "Motion", "TongueModel", "prepare_targets", "simulate"]
