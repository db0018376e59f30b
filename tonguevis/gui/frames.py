"""Per-frame drawing data of a simulated motion, computed once (no Qt).

The GUI never waits on the simulation during playback: after a simulation,
:class:`MotionFrames` reconstructs the full-mesh displacement of every frame
in batches (vectorised over frames) and stores what the 3D view draws, in
float32: deformed node positions, displacement magnitude and elastic energy
density per node.  Playback then only copies one frame's arrays into the
render buffers.
"""

from __future__ import annotations

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.gui.energy_density import EnergyDensity

#: Frames reconstructed per batch: big enough to vectorise, small enough that a
#: batch's float64 temporaries stay a few tens of MB on the paper's mesh.
BATCH = 128

#: Scalar quantities per node, with the unit the colour bar shows.
SCALARS = {
    "displacement": ("displacement", "mm"),
    "energy": ("energy density", "J/m³"),
}


def model_material(model) -> tuple[float, float]:
    """(Young's modulus Pa, Poisson's ratio) of a tongue model (paper defaults if absent)."""
    from tonguevis.sim.material import Material

    material = getattr(model, "material", None) or Material()
    return float(material.young), float(material.poisson)


class MotionFrames:
    """Everything the 3D view draws, for every frame of ``motion``.

    Attributes (F frames, n nodes, S driving sensors):
    points : (F, n, 3) float32, deformed node positions, metres.
    scalars : dict name -> (F, n) float32; ``displacement`` in mm (|u|),
        ``energy`` in J/m³ (density of the unwarped modal displacement Φq,
        whose volume integral is the motion's energy ½ qᵀΛq).
    sensor_points : (F, S, 3) float32, the driving sensors' nodes, deformed.
    targets : (F, S, 3) float32, measured (aligned) sensor positions.
    clim : dict name -> (low, high) colour range over the whole motion.
    """

    def __init__(self, motion, progress: ProgressCallback | None = None, batch: int = BATCH):
        model = motion.model
        rest = np.asarray(model.mesh.points, dtype=np.float64)
        self.motion = motion
        self.times = np.asarray(motion.times, dtype=np.float64)
        n_frames, n_nodes = len(self.times), len(rest)
        density = EnergyDensity(rest, model.mesh.tets, *model_material(model))
        self.points = np.empty((n_frames, n_nodes, 3), dtype=np.float32)
        self.scalars = {
            "displacement": np.empty((n_frames, n_nodes), dtype=np.float32),
            "energy": np.empty((n_frames, n_nodes), dtype=np.float32),
        }
        # Strains are linear in q (of the unwarped Φq): one dense product per batch.
        phi = model.basis(motion.q.shape[1]).phi
        strain_modes = np.asarray(density.strain_operator() @ phi, dtype=np.float32).T  # (m, 6k)
        q32 = np.asarray(motion.q, dtype=np.float32)
        for start in range(0, n_frames, batch):
            report(progress, start, n_frames, "reconstructing the mesh of every frame")
            frames = slice(start, min(start + batch, n_frames))
            u = model.displacements(motion.q[frames], warping=motion.warping, dtype=np.float32)
            self.points[frames] = rest + u
            self.scalars["displacement"][frames] = 1e3 * np.linalg.norm(u, axis=2)
            self.scalars["energy"][frames] = density.to_nodes(density.from_strains(q32[frames] @ strain_modes))
        report(progress, n_frames, n_frames, "frames ready")
        nodes = np.asarray(motion.sensor_nodes, dtype=np.int64)
        self.sensor_points = self.points[:, nodes, :]
        self.targets = np.asarray(motion.targets, dtype=np.float32)
        # Energy concentrates at the anchors: a lower percentile keeps the rest of the tongue readable.
        self.clim = {"displacement": _colour_range(self.scalars["displacement"], 99.5),
                     "energy": _colour_range(self.scalars["energy"], 98.0)}

    @property
    def n_frames(self) -> int:
        return int(len(self.times))

    def frame_at(self, t: float) -> int:
        """Index of the frame nearest time ``t`` (seconds), clipped."""
        from tonguevis.sim.motion import nearest_frame

        return nearest_frame(self.times, t)


def _colour_range(values: np.ndarray, percentile: float) -> tuple[float, float]:
    """0 to a high percentile over all frames (a few extreme nodes do not wash out the rest)."""
    finite = values[np.isfinite(values)]
    high = float(np.percentile(finite, percentile)) if finite.size else 1.0
    return (0.0, high if high > 0 else 1.0)
