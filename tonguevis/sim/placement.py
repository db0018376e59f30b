"""The tongue model placed in a speaker: the shipped mesh moved by a similarity, its modes derived.

A recording's rest sensors are fitted onto the model's landmark nodes by a similarity
T (recording -> model, :func:`tonguevis.preprocess.fit_similarity`, scale s of about
0.5-0.6 on the Opti-Speech speakers, 1.3 on Haskins).  Instead of shrinking the speaker
onto the model, :class:`PlacedModel` moves the model into the speaker by P = T⁻¹
(x' = c Q x + b, c = 1/s): every figure is then in the speaker's own head-corrected
frame and millimetres, and the sensors drive it with their own displacements.

The modes need no new eigen-solve.  For linear tets and an isotropic material, moving the
mesh by P gives, with Q_b the rotation applied to each node's three components,

    K' = c Q_b K Q_bᵀ,      M' = f c³ Q_b M Q_bᵀ   (f: the density's factor),

so λ' = λ / (f c²) and the mass-normalised modes are φ' = Q_b φ / √(f c³)
(:func:`placed_basis`; a test proves both equal to an eigen-solve of the moved mesh).

Which density: ``keep_frequencies=True`` (what :func:`tonguevis.sim.simulate` uses) scales
it by f = 1/c², so the placed tongue vibrates at the model's own frequencies (λ' = λ).  The
paper's material and Rayleigh damping (α, β) were chosen together for the model's
frequencies, and the dynamic solve runs at the recording's rate: with them kept the
placed simulation is *exactly* the model-frame one seen through P (node positions,
rotations, volume change, amplification; lengths times c), which is what makes the change
of frame safe to make.  Young's modulus stays the paper's, so the elastic energy is that
of the same tissue strained the same way in a body c³ times the volume (J).  With
``keep_frequencies=False`` the material is the model's, unchanged, and a tongue c times
larger is c times slower (λ' = λ / c²): the dynamics then differ from the model frame's.
"""

from __future__ import annotations

import hashlib
from dataclasses import replace
from functools import cached_property
from typing import Any

import numpy as np

from tonguevis.mesh.tetmesh import TetMesh
from tonguevis.sim.modal import ModalBasis
from tonguevis.sim.model import TongueModel

FRAMES = ("speaker", "model")


def placement_key(transform, density_factor: float) -> str:
    """Hex digest of a placement (scale, rotation, translation, density factor), for basis keys."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(transform.matrix, dtype=np.float64).tobytes())
    h.update(np.float64(density_factor).tobytes())
    return h.hexdigest()[:16]


def placed_basis(basis: ModalBasis, rotation: np.ndarray, scale: float, density_factor: float = 1.0,
                 key: str = "") -> ModalBasis:
    """The modes of a mesh moved by x' = scale · rotation · x + b, its density times ``density_factor``.

    basis : the source mesh's mass-normalised modes (3n, m), node-major; rotation (3, 3) proper;
    scale c > 0.  Returns φ' = Q_b φ / √(f c³) (units m/kg^½ of the moved mesh) and
    λ' = λ / (f c²) (1/s²); anchors and free DOFs are the same node ids.
    """
    n3, m = basis.phi.shape
    c, f = float(scale), float(density_factor)
    q = np.asarray(rotation, dtype=np.float64)
    phi = np.einsum("ij,njm->nim", q, basis.phi.reshape(n3 // 3, 3, m)).reshape(n3, m)
    phi /= np.sqrt(f * c ** 3)
    info = {k: v for k, v in basis.info.items() if k != "stiffness"}
    info.update({"placed_from": basis.key, "placement_scale": c, "density_factor": f})
    return ModalBasis(phi, basis.eigenvalues / (f * c * c), basis.free_dofs.copy(), key, info)


class PlacedModel(TongueModel):
    """``source`` moved by the similarity ``placement`` (x' = c Q x + b, metres): same tets, node ids,
    landmarks, anchors and Young's modulus; modes derived from the source's (cached) ones.

    keep_frequencies : density scaled by 1/c² so the eigenvalues equal the source's (see the module
        docstring); False keeps the source's material as it is.
    """

    def __init__(self, source: TongueModel, placement, keep_frequencies: bool = True):
        self.source = source
        self.placement = placement
        self.keep_frequencies = bool(keep_frequencies)
        self.density_factor = 1.0 / placement.scale ** 2 if keep_frequencies else 1.0
        material = replace(source.material, density=source.material.density * self.density_factor)
        meta = {**source.mesh.metadata, "placed": {"scale": placement.scale,
                                                   "matrix": placement.matrix.tolist()}}
        mesh = TetMesh(placement.apply(source.mesh.points), source.mesh.tets, metadata=meta)
        super().__init__(mesh, source.landmarks, material)

    def basis_key(self, m: int) -> str:
        return f"{self.source.basis_key(m)}-placed-{placement_key(self.placement, self.density_factor)}"

    def basis(self, m: int = 100, progress=None, cache: bool = True) -> ModalBasis:
        """The source's ``m`` modes (its memory or disk cache, else solved once there), moved: no eigen-solve."""
        if m not in self._bases:
            source = self.source.basis(m, progress=progress, cache=cache)
            self._bases[m] = placed_basis(source, self.placement.rotation, self.placement.scale,
                                          self.density_factor, self.basis_key(m))
        return self._bases[m]

    @cached_property
    def dorsal_nodes(self) -> np.ndarray:
        """The source's: which nodes a sensor may sit on is the model's anatomy, not the speaker's head pose."""
        return self.source.dorsal_nodes

    def placed(self, transform, keep_frequencies: bool = True) -> "PlacedModel":
        """The source placed by ``transform`` after this placement (one move, not a chain)."""
        return PlacedModel(self.source, transform @ self.placement, keep_frequencies)

    def __repr__(self) -> str:
        return f"PlacedModel(scale {self.placement.scale:.3f} of {self.source!r})"


def placed_model_of(model: Any) -> "PlacedModel | None":
    """The :class:`PlacedModel` ``model`` is (or, a sensor-patch copy, is built on), else None."""
    for candidate in (model, getattr(model, "base_model", None)):
        if isinstance(candidate, PlacedModel):
            return candidate
    return None


def source_model(model: Any) -> Any:
    """The unplaced model under ``model`` (itself when not placed; through sensor-patch copies too)."""
    return getattr(model, "source", None) or getattr(getattr(model, "base_model", None), "source", None) or model


def model_placement(model: Any):
    """The similarity placing ``model``'s source (model frame -> this model's frame), or None."""
    return getattr(model, "placement", None) or getattr(getattr(model, "base_model", None), "placement", None)


def in_model_frame(surface, model: Any):
    """A surface in the model frame (e.g. the generic palate, a PalateSurface) carried into ``model``'s frame."""
    placement = model_placement(model)
    if placement is None:
        return surface
    moved = surface.transformed(placement.rotation, placement.scale, placement.translation)
    moved.metadata["frame"] = "placed model"
    return moved


def targets_in_frame(recording, model: TongueModel, frame: str = "speaker", landmarks: str = "speaker",
                     rest=None, smooth_window: int | None = None, keep_frequencies: bool = True):
    """The model and the sensor targets in ``frame``: (model, :class:`~tonguevis.preprocess.PreparedTargets`, fit).

    Both frames start alike: :func:`~tonguevis.preprocess.prepare_targets` fits the similarity T
    (recording -> model) of the rest sensors onto the model's rule nodes.  "model" (the paper's
    way) returns them as they are: the speaker scaled and turned onto the model.  "speaker"
    places the model in the speaker by T⁻¹ (:class:`PlacedModel`) and carries the targets back
    with it (the same numbers seen through T⁻¹, so the sensor nodes are the same node ids): the
    displacements are then the speaker's own (head- and jaw-corrected, metres), the transform
    the identity, and a speaker's palate needs no moving.

    fit : what ``motion.metadata["fit"]`` says: the frame, T (scale, rotation, translation in
    metres of the model frame, its 4x4 matrix) and the residual of the rest sensors from their
    rule nodes (rms and max, mm in ``frame``; :func:`describe_fit` words it).
    """
    from tonguevis.errors import SimulationError
    from tonguevis.preprocess.alignment import SimilarityTransform
    from tonguevis.preprocess.targets import prepare_targets

    if frame not in FRAMES:
        raise SimulationError(f"frame must be one of {', '.join(FRAMES)}, got {frame!r}",
                              recording.metadata.get("file"))
    prep = prepare_targets(recording, model, landmarks, rest, smooth_window)
    fit = prep.transform
    if frame == "speaker":
        placement = fit.inverse()
        model = model.placed(placement, keep_frequencies=keep_frequencies)
        linear = placement.scale * placement.rotation
        prep = replace(
            prep, displacement=prep.displacement @ linear.T, aligned_rest=placement.apply(prep.aligned_rest),
            jaw_offset=None if prep.jaw_offset is None else prep.jaw_offset @ linear.T,
            transform=SimilarityTransform(1.0, np.eye(3), np.zeros(3)), alignment_rms=placement.scale * prep.alignment_rms)
    rule = model.mesh.points[[int(model.landmarks.sensors[n]) for n in prep.names]]
    residual = 1e3 * np.linalg.norm(prep.aligned_rest - rule, axis=1)
    info = {
        "frame": frame, "scale": fit.scale, "rotation": fit.rotation.tolist(), "translation_m": fit.translation.tolist(),
        "matrix": fit.matrix.tolist(), "midsagittal": bool(prep.midsagittal),
        "residual_rms_mm": float(np.sqrt(np.mean(residual ** 2))), "residual_max_mm": float(residual.max()),
        "residual_by_sensor_mm": {n: float(r) for n, r in zip(prep.names, residual)},
        "model_volume_cm3": float(1e6 * model.rest_volume),
        **({"density_factor": model.density_factor} if frame == "speaker" else {}),
    }
    return model, prep, info


def describe_fit(fit: dict) -> str:
    """One line on the frame of a motion and its fit, for summaries (``motion.metadata["fit"]``)."""
    scale = fit["scale"]
    residual = f"rest sensors {fit['residual_rms_mm']:.2f} mm RMS ({fit['residual_max_mm']:.2f} max) from the model's nodes"
    if fit["frame"] == "speaker":
        return (f"frame: the speaker's (head-corrected, mm as recorded): the model placed in the speaker, scaled by "
                f"{1 / scale:.3f} (tongue {fit['model_volume_cm3']:.0f} cm³); {residual}")
    return (f"frame: the model's (the speaker scaled by {scale:.3f} onto the generic tongue: mm are the model's, "
            f"not the speaker's); {residual}")


def modal_scale(model: Any) -> float:
    """k with q_model = k · q_source for the same shape (strain field): the modal coordinates of a placed
    model relative to its source's (φ' = Q_b φ / √(f c³) and lengths times c give k = c √(f c³)); 1 unplaced."""
    placed = placed_model_of(model)
    if placed is None:
        return 1.0
    c = placed.placement.scale
    return float(c * np.sqrt(placed.density_factor * c ** 3))
