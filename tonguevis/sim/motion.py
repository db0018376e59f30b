"""The result of a simulation: :class:`Motion`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from tonguevis.sim.model import TongueModel


def nearest_frame(times: np.ndarray, t: float) -> int:
    """Index of the sample of the sorted ``times`` (s) nearest ``t``, clipped to the ends."""
    i = int(np.searchsorted(times, t))
    if i <= 0:
        return 0
    if i >= len(times):
        return len(times) - 1
    return i if times[i] - t < t - times[i - 1] else i - 1



def frame_label(i: int, n_frames: int) -> str:
    """"frame 152/1888": frame ``i`` of ``n_frames``, numbered from 0 to ``n_frames - 1``.

    The one numbering of frames everywhere: ``tonguevis view --frame N``, the transport, the
    views' captions, the exports (``frame_00000.vtu``, the XDMF's ``/frames``) and Python
    (``motion.displacement(i)``) all count from 0; the figure after the slash is the last frame."""
    return f"frame {int(i)}/{int(n_frames) - 1}"

@dataclass
class Motion:
    """A simulated tongue motion on one :class:`TongueModel`.

    Attributes
    ----------
    times : (F,) float64, seconds (the recording's clock).
    q : (F, m) float64, modal displacements (mass-normalised modes, so q has
        units of m·kg^½).  The mesh's displacement is not stored: it is rebuilt
        from q when asked for, one frame (:meth:`displacement`), a selection
        (:meth:`displacements`) or chunk by chunk (:meth:`iter_displacements`),
        which keeps a long recording's memory to q and the per-frame figures;
        :func:`tonguevis.sim.xdmf.write_xdmf` exports it for ParaView.
    model : the :class:`TongueModel` (mesh, landmarks, modal basis).
    warping : whether the displacement is modal-warped (else linear Φq).
    sensor_names : list of S driving sensor names.
    sensor_nodes : (S,) int64 mesh node of each driving sensor.
    targets : (F, S, 3) float64, aligned EMA positions (metres, model frame).
    sensor_residual : (F, S) float64, |warped sensor node - target| in metres.
    energy : (F,) float64, elastic energy U = ½ qᵀΛq in joules.
    volume_change : (F,) float64, (V - V_rest) / V_rest of the warped mesh.
    converged : (F,) bool, whether Newton met the constraint tolerance.
    metadata : recording source, alignment, settings.
    penetration : (F,) metres, the deepest tongue node inside the palate (sensor
        conflicts excluded), or None when simulated without a palate.
    contact_area : (F,) m², the tongue surface within 0.3 mm of the palate, or None.
    jaw_offset : (F, 3) metres, the jaw's translation from rest in the model
        frame (what carries the tongue from the jaw's frame, where it is
        simulated, into the head's frame, where the palate is), or None.
    palate : the palate as the simulation placed it, at rest (velum down), in the simulation's frame, or
        None; kept in memory only: a loaded motion has none (:func:`tonguevis.sim.simulate.placed_palate`
        places it again).  :meth:`palate_at` gives it at a frame.
    velum_lift : (F,) metres, the velum's lift per frame (:mod:`tonguevis.sim.speaker_palate`), or None (a
        rigid palate, or none).
    """

    times: np.ndarray
    q: np.ndarray
    model: "TongueModel"
    warping: bool
    sensor_names: list[str]
    sensor_nodes: np.ndarray
    targets: np.ndarray
    sensor_residual: np.ndarray
    energy: np.ndarray
    volume_change: np.ndarray
    converged: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)
    penetration: np.ndarray | None = None
    contact_area: np.ndarray | None = None
    jaw_offset: np.ndarray | None = None
    #: the palate as the simulation placed it (model frame; a PalateSurface), in memory only (not saved)
    palate: Any = field(default=None, repr=False, compare=False)
    velum_lift: np.ndarray | None = None

    def palate_at(self, index: int):
        """The palate at frame ``index`` (a PalateSurface in the simulation's head frame: the velum lifted as
        the simulation lifted it), or None without one; ``palate_at(i).clearance(points)`` measures against it."""
        if self.palate is None:
            return None
        if self.velum_lift is None:
            return self.palate
        return self.palate.lifted(float(self.velum_lift[int(index)]))

    @property
    def n_frames(self) -> int:
        return int(len(self.times))

    def frame_at(self, t: float) -> int:
        """Index of the frame nearest time ``t`` (seconds), clipped to the motion."""
        return nearest_frame(self.times, t)

    def displacement(self, i: int) -> np.ndarray:
        """(n, 3) displacement of every mesh node at frame ``i``, metres (reconstructed from q[i])."""
        return self.model.displacement(self.q[i], warping=self.warping)

    def displacements(self, frames: np.ndarray | slice | None = None, nodes: np.ndarray | None = None,
                      dtype=np.float64) -> np.ndarray:
        """(F', n, 3) displacements of the selected frames (all by default), metres.

        The whole array is O(frames × nodes): F' × n × 3 × 8 bytes, 1.3 GB for five
        minutes at 100 Hz on 1,800 nodes.  For a long motion select frames (a slice, an
        index array) or walk through it with :meth:`iter_displacements`.  ``nodes``:
        (k,) node ids to reconstruct instead of the whole mesh (F', k, 3).
        """
        q = self.q if frames is None else self.q[frames]
        return self.model.displacements(q, warping=self.warping, dtype=dtype, nodes=nodes)

    def iter_displacements(self, chunk: int | None = None, frames: np.ndarray | slice | None = None,
                           nodes: np.ndarray | None = None, dtype=np.float64):
        """Yield ``(indices, displacements)`` chunk by chunk, in bounded memory.

        indices : (c,) int64 frame numbers of the chunk (at most ``chunk``, default
        :data:`~tonguevis.sim.model.CHUNK_FRAMES`); displacements : (c, n, 3) metres
        (``dtype``; (c, k, 3) for ``nodes``), equal to ``displacements()[indices]``.
        ``frames`` selects frames (a slice such as ``slice(None, None, 4)`` or
        an index array), default all.  Each chunk is reconstructed from q when
        it is reached, so a 30-minute motion costs one chunk's memory
        (256 frames × 1,800 nodes: 11 MB in float64).
        """
        from tonguevis.sim.model import CHUNK_FRAMES

        chunk = CHUNK_FRAMES if chunk is None else int(chunk)
        if chunk < 1:
            raise ValueError(f"chunk must be at least 1 frame, got {chunk}")
        idx = np.arange(self.n_frames) if frames is None else np.arange(self.n_frames)[frames]
        idx = np.atleast_1d(idx).astype(np.int64)
        for start in range(0, len(idx), chunk):
            sel = idx[start:start + chunk]
            yield sel, self.model.displacements(self.q[sel], warping=self.warping, dtype=dtype, nodes=nodes)

    def deformed_points(self, i: int) -> np.ndarray:
        """(n, 3) deformed node positions at frame ``i``, metres."""
        return self.model.mesh.points + self.displacement(i)

    # ------------------------------------------------------------------ files
    def save(self, path) -> None:
        """Write the motion as ``.npz`` (no pickle; temporary file, then rename).

        The model is stored by its mesh, anchors, sensor landmarks and material,
        so :meth:`load` rebuilds it (the modal basis comes from the cache or is
        solved again, deterministically).  Uncompressed: q hardly compresses
        (118 of 145 MB for 30 minutes) and deflating it took two minutes;
        stored, it is about 6 MB per minute of a 100 Hz recording.
        """
        import json
        from pathlib import Path

        from tonguevis._files import atomic_write

        path = Path(path)
        model = self.model
        meta = {
            "metadata": self.metadata,
            "sensor_names": list(self.sensor_names),
            "warping": bool(self.warping),
            "material": model.material.as_dict(),
            "landmark_sensors": {k: int(v) for k, v in model.landmarks.sensors.items()},
            "format": "tonguevis-motion",
            "version": 1,
        }
        from tonguevis.sim.placement import placed_model_of
        from tonguevis.sim.rest_fit import rest_fitted_model_of

        fitted = rest_fitted_model_of(model)  # the rest shape fitted on a placement: that placement, then the fit
        placed = placed_model_of(fitted.unfitted if fitted is not None else model)
        if fitted is not None:
            meta["rest_fit"] = fitted.rest_fit
        if placed is not None:  # placed in a speaker: the source mesh and the move, so load derives the modes
            move = placed.placement  # its parts as they are: the loaded mesh then equals this one bit for bit
            meta["placement"] = {"matrix": move.matrix.tolist(), "scale": move.scale, "rotation": move.rotation.tolist(),
                                 "translation": move.translation.tolist(), "keep_frequencies": placed.keep_frequencies,
                                 "source_material": placed.source.material.as_dict()}
        def write(tmp):
            with open(tmp, "wb") as fh:
                np.savez(
                    fh,
                    times=self.times,
                    q=self.q,
                    sensor_nodes=self.sensor_nodes,
                    targets=self.targets,
                    sensor_residual=self.sensor_residual,
                    energy=self.energy,
                    volume_change=self.volume_change,
                    converged=self.converged,
                    **{k: v for k, v in (("penetration", self.penetration), ("contact_area", self.contact_area),
                                         ("jaw_offset", self.jaw_offset),
                                         ("velum_lift", self.velum_lift)) if v is not None},
                    points=model.mesh.points,
                    tets=model.mesh.tets,
                    anchors=model.anchors,
                    **({"source_points": placed.source.mesh.points} if placed is not None else {}),
                    # the pressure subspace of a motion with its volume kept (tonguevis.sim.volume): q's last columns
                    **({"volume_basis": model._bases[self.q.shape[1]].phi[:, -model.volume_columns:]}
                       if getattr(model, "volume_columns", 0) else {}),
                    meta=np.array(json.dumps(meta, default=_json_default)),
                )

        atomic_write(path, write)

    @classmethod
    def load(cls, path) -> "Motion":
        """Read a motion written by :meth:`save`; a bad file raises SimulationError."""
        import json
        import zipfile
        from types import SimpleNamespace

        from tonguevis.errors import SimulationError
        from tonguevis.mesh.tetmesh import TetMesh
        from tonguevis.sim.material import Material
        from tonguevis.sim.model import TongueModel

        try:
            with np.load(path, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                if meta.get("format") != "tonguevis-motion":
                    raise SimulationError("not a tonguevis motion file", path)
                arrays = {k: np.array(data[k]) for k in data.files if k != "meta"}
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError) as exc:
            raise SimulationError(f"cannot read motion file: {exc}", path) from exc
        landmarks = SimpleNamespace(sensors=meta["landmark_sensors"], anchors=arrays["anchors"])
        placement = meta.get("placement")
        if placement is not None:  # a model placed in the speaker: the shipped modes (cache), moved
            from tonguevis.preprocess.alignment import SimilarityTransform
            from tonguevis.sim.placement import PlacedModel

            if "scale" in placement:
                move = SimilarityTransform(placement["scale"], placement["rotation"], placement["translation"])
            else:  # the 4x4 matrix alone
                matrix = np.asarray(placement["matrix"], dtype=np.float64)
                scale = float(np.cbrt(np.linalg.det(matrix[:3, :3])))
                move = SimilarityTransform(scale, matrix[:3, :3] / scale, matrix[:3, 3])
            source = TongueModel(TetMesh(arrays["source_points"], arrays["tets"], metadata={"file": str(path)}),
                                 landmarks, Material(**placement["source_material"]))
            model = PlacedModel(source, move, placement["keep_frequencies"])
            if meta.get("rest_fit") is not None:  # bent onto the rest sensors: the saved rest shape on that placement
                from tonguevis.sim.rest_fit import RestFittedModel

                model = RestFittedModel(model, None, meta["rest_fit"], points=arrays["points"])
        else:
            mesh = TetMesh(arrays["points"], arrays["tets"], metadata={"file": str(path)})
            model = TongueModel(mesh, landmarks, Material(**meta["material"]))
        patches = meta["metadata"].get("sensor_patches")
        if patches:  # the same Ritz basis again: the modes (cache) and the patch shapes (deterministic)
            from tonguevis.sim.patches import augmented_basis, augmented_model

            basis = augmented_basis(model, model.basis(int(patches["global_modes"])), np.array(patches["nodes"]),
                                    1e-3 * float(patches["radius_mm"]), 1e-3 * float(patches["reach_mm"]),
                                    None if not patches.get("hump_mm") else tuple(1e-3 * np.asarray(patches["hump_mm"])),
                                    patches.get("humped"), unit=bool(patches.get("unit_at_node", False)))
            model = augmented_model(model, basis)
        domains = meta["metadata"].get("domains")
        if meta["metadata"].get("method") == "domains" and domains:  # q is z: the same domain subspace again
            from tonguevis.sim.domains import DomainModel, domains_model

            model = domains_model(model, DomainModel(model, np.array(domains["seeds"][:-1])))
        if "volume_basis" in arrays:  # the volume kept: the stored pressure subspace after the basis
            from tonguevis.sim.volume import volume_kept_model

            extra = arrays["volume_basis"]
            model = volume_kept_model(model, arrays["q"].shape[1] - extra.shape[1], extra)
        return cls(
            times=arrays["times"], q=arrays["q"], model=model, warping=meta["warping"],
            sensor_names=meta["sensor_names"], sensor_nodes=arrays["sensor_nodes"],
            targets=arrays["targets"], sensor_residual=arrays["sensor_residual"],
            energy=arrays["energy"], volume_change=arrays["volume_change"],
            converged=arrays["converged"].astype(bool), metadata=meta["metadata"],
            penetration=arrays.get("penetration"), contact_area=arrays.get("contact_area"),
            jaw_offset=arrays.get("jaw_offset"), velum_lift=arrays.get("velum_lift"),
        )

    def to_vtk_series(self, folder, frames=None, progress=None, frame: str = "head"):
        """Write ``motion.pvd`` + one ``.vtu`` per frame (ParaView) and a README.txt; returns the .pvd path.

        frame : "head" (default: the tongue carried by the jaw's translation, the palate's
        frame) or "jaw" (as simulated).  Point data: displacement (m, from rest in that frame)
        and its magnitude displacement_mm, deformation (m, the tongue's own, jaw frame); see
        :func:`tonguevis.sim.vtk_series.write_vtk_series`.
        """
        from tonguevis.sim.vtk_series import write_vtk_series

        return write_vtk_series(self, folder, frames=frames, frame=frame, progress=progress)


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    return str(obj)


def rest_of(motion):
    """The :class:`~tonguevis.preprocess.rest.RestChoice` a motion was simulated with (None for motions saved
    before it was recorded)."""
    from tonguevis.preprocess.rest import RestChoice

    data = getattr(motion, "metadata", {}).get("rest")
    return RestChoice.from_dict(data) if isinstance(data, dict) and "interval" in data else None
