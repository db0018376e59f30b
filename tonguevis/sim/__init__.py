"""The physics: FEM assembly, modal basis, modal warping and constrained Newmark integration."""

from tonguevis.sim.material import Material
from tonguevis.sim.modal import ModalBasis
from tonguevis.sim.model import TongueModel
from tonguevis.sim.motion import Motion
from tonguevis.sim.settings import RunSettings, build_model
from tonguevis.sim.simulate import prepare_targets, simulate

__all__ = ["Material", "ModalBasis", "Motion", "RunSettings", "TongueModel", "build_model", "prepare_targets", "simulate"]
