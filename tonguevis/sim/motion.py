"""The result of a simulation: :class:`Motion`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from tonguevis.sim.model import TongueModel


@dataclass
class Motion:
    """A simulated tongue motion on one :class:`TongueModel`.

    Attributes
    ----------
    times : (F,) float64, seconds (the recording's clock).
    q : (F, m) float64, modal displacements (mass-normalised modes, so q has
        units of m·kg^½).
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

    @property
    def n_frames(self) -> int:
        return int(len(self.times))

    def frame_at(self, t: float) -> int:
        """Index of the frame nearest time ``t`` (seconds), clipped to the motion."""
        i = int(np.searchsorted(self.times, t))
        if i <= 0:
            return 0
        if i >= self.n_frames:
            return self.n_frames - 1
        return i if self.times[i] - t < t - self.times[i - 1] else i - 1

    def displacement(self, i: int) -> np.ndarray:
        """(n, 3) displacement of every mesh node at frame ``i``, metres."""
        return self.model.displacement(self.q[i], warping=self.warping)

    def displacements(self, frames: np.ndarray | slice | None = None) -> np.ndarray:
        """(F', n, 3) displacements of the selected frames (all by default), metres."""
        q = self.q if frames is None else self.q[frames]
        return self.model.displacements(q, warping=self.warping)

    def deformed_points(self, i: int) -> np.ndarray:
        """(n, 3) deformed node positions at frame ``i``, metres."""
        return self.model.mesh.points + self.displacement(i)
