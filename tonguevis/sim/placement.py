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
from tonguevis.sim.settings import ADULT, FRAMES  # noqa: F401 (re-exported)

#: Tongue volumes, as multiples of the shipped model's (about 100 cm³, an adult's), taken for an adult's.
#: The alignment's size falls well outside on the shared Opti-Speech speaker (4.4-6.6 times: coils
#: spread wider than the paper's placement rule) and inside on the demo speakers and Haskins (0.9-1.4).
ADULT_VOLUMES = (0.5, 2.0)


#: Rest sensors further than this from their nodes (mm RMS) are said in a warning: the model's rest shape is
#: then not the speaker's.  The shared recordings stay under it (Opti-Speech 1.2-1.8 mm at the adult size,
#: Haskins 4.0, the 0.1 s of rticulate's AG500 4.5); a held-out Opti-Speech speaker's 6.2 mm passed unsaid.
REST_MISFIT_MM = 5.0


def _file_name(recording) -> str:
    """The recording's file name without its folders, for a warning's one line."""
    from pathlib import Path

    return Path(str(recording.metadata.get("file") or "recording")).name


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

    def rotation_matrix(self, basis: ModalBasis) -> np.ndarray:
        """W' = C'φ' (3n, m) of this model's placed modes, from the source's W (cached there) as its modes are moved.

        On the moved mesh ∇' = det(Q) Q ∇ / c for a rotation vector (a pseudo-vector) and φ' = Q_b φ / √(f c³),
        so C'φ' = det(Q) Q_b (C φ) / (c √(f c³)): no curl operator of this mesh (its assembly cost some
        60 ms in every simulate() in the speaker's frame), the same W to rounding (tests/test_speaker_frame.py).
        Any other basis: its own curl operator, as :meth:`TongueModel.rotation_matrix`.
        """
        m = basis.phi.shape[1]
        source = self.source._bases.get(m)
        if basis.key in self._rotation_matrices or basis.key != self.basis_key(m) or source is None:
            return super().rotation_matrix(basis)
        q = np.asarray(self.placement.rotation, dtype=np.float64)
        c, f = float(self.placement.scale), float(self.density_factor)
        w = self.source.rotation_matrix(source)
        moved = np.einsum("ij,njm->nim", q, w.reshape(-1, 3, m)).reshape(w.shape)
        moved *= np.sign(np.linalg.det(q)) / (c * np.sqrt(f * c ** 3))
        self._rotation_matrices[basis.key] = moved
        return moved

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
    """The unplaced model under ``model`` (itself when not placed; through sensor-patch copies and a rest
    shape fitted on a placement too)."""
    from tonguevis.sim.rest_fit import rest_fitted_model_of

    fitted = rest_fitted_model_of(model)
    if fitted is not None:
        model = fitted.unfitted
    return getattr(model, "source", None) or getattr(getattr(model, "base_model", None), "source", None) or model


def modal_transfer(source: Any, target: Any, linear: np.ndarray, modes: int) -> tuple[np.ndarray, np.ndarray]:
    """(T (m, m), residual (3n, m)): the coordinates on ``target``'s ``modes`` modes of the shapes of
    ``source``'s, turned and scaled by ``linear`` (3, 3) node by node: q_target = T q_source with
    T = Φₜᵀ Mₜ (L Φₛ), the mass-weighted least-squares fit (Φₜ is mass-normalised); ``residual`` (m per
    unit q) = L Φₛ - Φₜ T, what it misses.

    Two placements of one tongue share their modes up to the placement (T is then the modal scale times
    the identity, the residual zero to rounding); two tongues bent onto different rests
    (:mod:`tonguevis.sim.rest_fit`) have nearby but different modes, and T carries one's shapes onto
    the other's as closely as its modes can draw them.
    """
    phi_s = source.basis(modes).phi
    n3 = phi_s.shape[0]
    phi_t = target.basis(modes).phi
    moved = np.einsum("ij,njm->nim", np.asarray(linear, dtype=np.float64), phi_s.reshape(n3 // 3, 3, modes))
    moved = moved.reshape(n3, modes)
    transfer = phi_t.T @ (target.mass @ moved)
    return transfer, moved - phi_t @ transfer


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
                     rest=None, smooth_window: int | None = None, keep_frequencies: bool = True,
                     tongue_size: float | str | None = None, rest_fit: bool = False):
    """The model and the sensor targets in ``frame``: (model, :class:`~tonguevis.preprocess.PreparedTargets`, fit).

    Both frames start alike: :func:`~tonguevis.preprocess.prepare_targets` fits the similarity T
    (recording -> model) of the rest sensors onto the model's rule nodes.  "model" (the paper's
    way) returns them as they are: the speaker scaled and turned onto the model.  "speaker"
    places the model in the speaker by T⁻¹ (:class:`PlacedModel`) and carries the targets back
    with it (the same numbers seen through T⁻¹, so the sensor nodes are the same node ids): the
    displacements are then the speaker's own (head- and jaw-corrected, metres), the transform
    the identity, and a speaker's palate needs no moving.

    tongue_size : in the speaker frame, ``"adult"`` (:data:`ADULT`): as None when the alignment's size is an
        adult's (volume within :data:`ADULT_VOLUMES` of the model's), else as 1 (said in a warning;
        ``fit["size_from"]`` says which: "alignment", "adult norm" or "given").
        None (default): the model placed by T⁻¹ exactly, 1/s times its
        size (the model-frame motion exactly, seen in the speaker's units); on the Opti-Speech speaker
        that is a tongue of 430-650 cm³ (:func:`surface_fit` says why), and a placed tongue outside
        half to twice the model's volume is warned about.  A number: the speaker's tongue as that
        multiple of the model's (1: the generic adult tongue, about 100 cm³), turned and moved so that
        the speaker's rest sensors lie on its upper surface (:func:`surface_fit`), each sensor's node
        the nearest there; not the same simulation as the model frame's (the sensors sit on other parts
        of the tongue): on the shared recordings its held-out RMSE differs by -0.12 to +0.19 mm.

    rest_fit : the placed tongue then bent so that every sensor node sits on its rest sensor
        (:mod:`tonguevis.sim.rest_fit`; the fit's figures in ``fit["rest_fit"]``).

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
    how, rule_scale = "rule nodes", fit.scale
    size_from = "alignment"
    if frame == "speaker" and isinstance(tongue_size, str):
        if tongue_size != ADULT:
            raise SimulationError(f"the tongue size must be a positive multiple of the model's, None or "
                                  f"{ADULT!r}, got {tongue_size!r}", recording.metadata.get("file"))
        volume = fit.scale ** -3
        if ADULT_VOLUMES[0] <= volume <= ADULT_VOLUMES[1]:
            tongue_size = None  # the alignment's size is an adult's: kept
        else:
            from tonguevis._logging import warn_once

            warn_once(f"{_file_name(recording)}: tongue at the adult size; the rest sensors' spread says {volume:.1f} "
                      "times its volume (--tongue-size alignment keeps that)",
                      f"{recording.metadata.get('file', 'recording')}: the rest alignment would make the tongue "
                      f"{volume:.1f} times the generic one's volume (the rest sensors sit "
                      f"{'further apart' if volume > 1 else 'closer together'} than the model's placement rule), "
                      "which no adult tongue is: placed at the generic adult size instead, the rest sensors fitted "
                      "onto its upper surface")
            tongue_size, size_from = 1.0, "adult norm"
    elif frame == "speaker" and tongue_size is not None:
        size_from = "given"
    if frame == "speaker" and tongue_size is not None:
        if not (np.isfinite(tongue_size) and tongue_size > 0):
            raise SimulationError(f"the tongue size must be a positive multiple of the model's or None, got "
                                  f"{tongue_size!r}", recording.metadata.get("file"))
        rule_scale = fit.scale
        fit, _ = surface_fit(prep, model, 1.0 / tongue_size)
        how = "upper surface"
        placed = PlacedModel(model, fit.inverse(), keep_frequencies)
        from tonguevis.preprocess.alignment import SimilarityTransform as _Similarity

        prep = prepare_targets(recording, placed, landmarks, prep.rest, smooth_window,
                               transform=_Similarity(1.0, np.eye(3), np.zeros(3)))
        model = placed
    elif frame == "speaker":
        placement = fit.inverse()
        volume = placement.scale ** 3
        if not ADULT_VOLUMES[0] <= volume <= ADULT_VOLUMES[1]:
            from tonguevis._logging import warn_once

            warn_once(f"{_file_name(recording)}: at the rest alignment's size the tongue is {volume:.1f} times the "
                      "generic one's volume (--tongue-size 1, tongue_size=1: the generic size)",
                      f"{recording.metadata.get('file', 'recording')}: placed in the speaker as the rest alignment "
                      f"scales it ({placement.scale:.2f}), the tongue is {volume:.1f} times the generic one's volume: "
                      f"the rest sensors sit {'further apart' if volume > 1 else 'closer together'} than the model's "
                      "placement rule, which need not be the tongue's size; tongue_size=1 keeps the generic size, "
                      "the sensors fitted onto its surface")
        model = PlacedModel(model, placement, keep_frequencies)
        linear = placement.scale * placement.rotation
        prep = replace(
            prep, displacement=prep.displacement @ linear.T, aligned_rest=placement.apply(prep.aligned_rest),
            jaw_offset=None if prep.jaw_offset is None else prep.jaw_offset @ linear.T,
            transform=SimilarityTransform(1.0, np.eye(3), np.zeros(3)), alignment_rms=placement.scale * prep.alignment_rms)
    bent = None
    if rest_fit:
        from tonguevis.sim.rest_fit import rest_fitted

        model = rest_fitted(model, prep.nodes, prep.aligned_rest, recording.metadata.get("file"))
        bent = model.rest_fit
    # The residual: each rest sensor from the node it is fitted to (the rule nodes, or the surface nodes;
    # once the rest shape is fitted, the sensor nodes it was bent to meet).
    fitted = model.mesh.points[[int(model.landmarks.sensors[n]) for n in prep.names]] \
        if how == "rule nodes" and bent is None else model.mesh.points[prep.nodes]
    residual = 1e3 * np.linalg.norm(prep.aligned_rest - fitted, axis=1)
    rms = float(np.sqrt(np.mean(residual ** 2)))
    if rms > REST_MISFIT_MM:
        from tonguevis._logging import warn_once

        worst = int(np.argmax(residual))
        warn_once(f"{_file_name(recording)}: the rest sensors lie {rms:.1f} mm RMS from their nodes "
                  f"({prep.names[worst]} {residual[worst]:.1f} mm): the model's rest shape is not this speaker's"
                  + ("" if bent is not None else " (--fit-rest bends it onto them)"))
    info = {
        "frame": frame, "fitted_to": how, "tongue_size": None if frame == "model" else 1.0 / fit.scale,
        **({"size_from": size_from} if frame == "speaker" else {}),
        "scale": fit.scale, "rotation": fit.rotation.tolist(), "translation_m": fit.translation.tolist(),
        "rule_node_scale": rule_scale,  # what the rest sensors' fit onto the rule nodes says
        "matrix": fit.matrix.tolist(), "midsagittal": bool(prep.midsagittal),
        "residual_rms_mm": rms, "residual_max_mm": float(residual.max()),
        "residual_by_sensor_mm": {n: float(r) for n, r in zip(prep.names, residual)},
        "model_volume_cm3": float(1e6 * model.rest_volume),
        **({"density_factor": getattr(model, "density_factor", getattr(getattr(model, "unfitted", None),
                                                                      "density_factor", 1.0))}
           if frame == "speaker" else {}),
        **({"rest_fit": bent} if bent is not None else {}),
    }
    return model, prep, info


def describe_fit(fit: dict) -> str:
    """One line on the frame of a motion and its fit, for summaries (``motion.metadata["fit"]``)."""
    scale = fit["scale"]
    residual = (f"{fit['residual_rms_mm']:.2f} mm RMS ({fit['residual_max_mm']:.2f} max) from "
                + ("the model's nodes" if fit.get("fitted_to", "rule nodes") == "rule nodes"
                   else "their nodes on its upper surface"))
    if fit["frame"] == "speaker":
        implied = float(fit.get("rule_node_scale", float("nan"))) ** -3
        size = (f"at {1 / scale:.2f} x its size ({fit['model_volume_cm3']:.0f} cm³)"
                + (f", the generic adult size (the rest alignment's, {implied:.1f} times that volume, is no adult's), "
                   "the rest sensors fitted onto its upper surface" if fit.get("size_from") == "adult norm"
                   else ", the rest sensors fitted onto its upper surface" if fit.get("fitted_to") == "upper surface"
                   else ", as the rest alignment scales it"))
        if fit.get("rest_fit"):
            bent = fit["rest_fit"]
            if bent.get("fraction", 1.0) < 1.0:
                residual = (f"{bent['sensors_after_rms_mm']:.2f} mm RMS off their nodes, the rest shape bent "
                            f"{100 * bent['fraction']:.0f} % of the way onto them (all the way would crush tets; nodes "
                            f"moved up to {bent['moved_max_mm']:.1f} mm; they were {bent['sensors_before_rms_mm']:.2f} mm "
                            "RMS off)")
            else:
                residual = (f"on their nodes, the rest shape bent onto them (nodes moved up to "
                            f"{bent['moved_max_mm']:.1f} mm; they were {bent['sensors_before_rms_mm']:.2f} mm RMS off)")
        return f"frame: the speaker's (head-corrected, mm as recorded): the model placed in the speaker {size}; rest sensors {residual}"
    return (f"frame: the model's (the speaker scaled by {scale:.3f} onto the generic tongue: mm are the model's, "
            f"not the speaker's); rest sensors {residual}")


def size_note(fit: dict) -> str:
    """A short line when the tongue is not at the size its rest alignment implies because that is no adult's
    (``fit``: ``motion.metadata["fit"]``); "" otherwise."""
    if fit.get("size_from") != "adult norm":
        return ""
    implied = float(fit.get("rule_node_scale", float("nan"))) ** -3
    return (f"tongue at the generic adult size: the rest sensors' spread would make it {implied:.1f} times that "
            "(Simulation ▸ Tongue size)")


def modal_scale(model: Any) -> float:
    """k with q_model = k · q_source for the same shape (strain field): the modal coordinates of a placed
    model relative to its source's (φ' = Q_b φ / √(f c³) and lengths times c give k = c √(f c³)); 1 unplaced."""
    placed = placed_model_of(model)
    if placed is None:
        return 1.0
    c = placed.placement.scale
    return float(c * np.sqrt(placed.density_factor * c ** 3))


def surface_fit(prep, model: TongueModel, scale: float, iterations: int = 50):
    """(T, rms m): the similarity of fixed ``scale`` (recording -> model) putting the rest sensors on the model's
    upper surface: rotation and translation by ICP over its dorsal nodes (each sensor its own nearest node,
    :func:`~tonguevis.preprocess.targets.assign_sensor_nodes`), from the rule-node fit ``prep.transform``.

    Why a fixed scale: the rest sensors do not tell the speaker's size.  On the Opti-Speech speaker the
    rule-node fit says 0.53-0.61 (a tongue 1.6-1.9 times the generic one, 430-650 cm³ where adults have
    about 100), because that speaker's coils sit further apart than the paper's placement rule (laterals
    17-21 mm apart where the rule's nodes are 9 mm); yet the same sensors lie on the generic tongue's upper
    surface within 0.9-1.8 mm RMS at any scale from 0.6 to 1.0.  The size must come from elsewhere (a
    palate, an image, a norm); this fits the rest to it.
    """
    from tonguevis.preprocess.alignment import SimilarityTransform, fit_similarity
    from tonguevis.preprocess.targets import assign_sensor_nodes

    t = prep.transform
    source = t.inverse().apply(prep.aligned_rest)  # the rest sensors in the recording's frame (m)
    points, dorsal = model.mesh.points, model.dorsal_nodes

    def at_scale(rotation, target):
        return SimilarityTransform(scale, rotation, target.mean(axis=0) - scale * rotation @ source.mean(axis=0))

    current = at_scale(t.rotation, t.apply(source))  # the rule fit's pose, the centroids kept together
    nodes = None
    for _ in range(iterations):
        new = assign_sensor_nodes(current.apply(source), points, dorsal)
        if nodes is not None and np.array_equal(new, nodes):
            break
        nodes = new
        # The best rotation does not depend on the scale: take the free fit's, then this scale's translation.
        current = at_scale(fit_similarity(source, points[nodes], midsagittal=prep.midsagittal).rotation,
                           points[nodes])
    rms = float(np.sqrt(np.mean(np.sum((current.apply(source) - points[nodes]) ** 2, axis=1))))
    return current, rms


def carried(motion, model: Any):
    """``motion`` carried onto ``model``, another placement of the same tongue (e.g. recording B shown in
    A's speaker, to compare them): the same deformation (strain field, node by node) on ``model``'s
    placement, in its size.  Returns ``motion`` itself when it is on ``model`` already.

    The modal coordinates carry it: for the same strain, q = modal_scale(model) · q_source
    (:func:`modal_scale`; the rotation of a placement turns the modes with it), so ``model``'s own
    reconstruction draws it.  Sensor patches belong to B's sensors: only the modes are carried
    (:func:`tonguevis.sim.patches.global_part`).  Positions (targets) go through the source frame,
    displacements (jaw offset) by the linear part; energies scale with the volume (c³, the material
    the same).  Raises ModelError when the two are not placements of one model.
    """
    from dataclasses import replace as replaced

    from tonguevis.errors import ModelError
    from tonguevis.sim.patches import global_part

    if motion.model is model:
        return motion
    model = getattr(model, "base_model", model)  # a patched copy: its modes' model
    own, q = global_part(motion)
    if not same_source(own, model):
        raise ModelError("the two motions are on different tongue models: one cannot be carried onto the other")
    move = placement_between(own, model)
    linear = move.scale * move.rotation
    metadata = dict(motion.metadata)
    metadata["carried_onto"] = {"scale": move.scale, "matrix": move.matrix.tolist(),
                                "note": "this motion's deformation shown on another placement of the same tongue"}
    from tonguevis.sim.rest_fit import rest_fitted_model_of

    if rest_fitted_model_of(own) is None and rest_fitted_model_of(model) is None:
        carried_q = modal_scale(model) / modal_scale(own) * q  # the same modes, moved: exact
    else:
        # A rest shape fitted to a speaker: a body of its own, whose modes are near the other's but not its
        # own moved. The deformation is carried by its modal shapes, fitted onto this model's modes.
        transfer, residual = modal_transfer(own, model, linear, q.shape[1])
        carried_q = q @ transfer.T
        missed = np.linalg.norm((q @ residual.T).reshape(len(q), -1, 3), axis=2).max() if len(q) else 0.0
        metadata["carried_onto"].update(
            note="this motion's deformation carried onto another tongue (a rest shape fitted to another "
                 "speaker) through its modes", modal_fit_error_max_mm=float(1e3 * missed))
    metadata.pop("sensor_patches", None)
    return replaced(
        motion, q=carried_q, model=model,
        targets=move.apply(motion.targets), energy=motion.energy * move.scale ** 3,
        sensor_residual=motion.sensor_residual * move.scale,
        jaw_offset=None if motion.jaw_offset is None else motion.jaw_offset @ linear.T,
        metadata=metadata, palate=None)


def placement_between(source: Any, target: Any):
    """The similarity from ``source``'s frame to ``target``'s, two placements of one tongue (either may be
    unplaced: the model frame)."""
    return (model_placement(target) or _identity()) @ (model_placement(source) or _identity()).inverse()


def _identity():
    from tonguevis.preprocess.alignment import SimilarityTransform

    return SimilarityTransform(1.0, np.eye(3), np.zeros(3))


def same_source(a: Any, b: Any) -> bool:
    """Whether two models are placements (or not) of one tongue model: mesh, anchors and material alike."""
    a, b = source_model(a), source_model(b)
    return a is b or (a.mesh.n_nodes == b.mesh.n_nodes and a.basis_key(1) == b.basis_key(1))


def frame_words(motion) -> str:
    """Which frame a motion's coordinates are in, for exports and captions: "the speaker's head-corrected
    frame (...)" or "the model frame (...)" (motions saved before the speaker frame: the model's)."""
    fit = getattr(motion, "metadata", {}).get("fit") or {}
    if fit.get("frame") == "speaker":
        return (f"the speaker's head-corrected frame: the tongue model placed in the speaker at "
                f"{1 / fit['scale']:.2f} x its size, the speaker's millimetres")
    return "the model frame: the speaker's sensors scaled onto the generic tongue, the model's millimetres"
