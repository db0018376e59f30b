"""The tongue's rest shape fitted to the speaker's rest sensors: a non-rigid fit on top of the placement.

The placement (:mod:`tonguevis.sim.placement`) fits the model to the speaker by a similarity:
scale, rotation, translation.  The rest sensors then still lie 2.7-3.3 mm (RMS) from their nodes
on the shared Opti-Speech recordings and 1.6 mm on the Haskins one, and the sensors are drawn that
far from where they were measured (each on its node's rest): the speaker's tongue is not the generic
one scaled.  :func:`fit_rest_shape` bends the placed tongue so that every sensor node
sits on its rest sensor: the displacement is the linear-elastic static response of the model's own
FEM to those prescribed nodal displacements, the anchors (jaw and hyoid) held,

    K_ff u_f = -K_fc u_c,     u_c = (rest sensor - node) at the sensor nodes, 0 at the anchors,

the smoothest shape the tissue takes to meet them.  :class:`RestFittedModel` is the tongue with that
rest shape (same tets, node ids, landmarks and material); its modes are solved anew for its own
geometry (about 2 s, cached on disk like any mesh's).

Measured on the four shared real recordings (speaker's frame, sensors on the surface, held-out
validation): held-out RMSE mean 3.50 -> 3.38 (/ta/ 009), 2.53 -> 2.47 (/ka/ 006), 2.15 -> 1.99
(/ka/ 007), 4.14 -> 4.08 mm (Haskins); per held-out sensor the model loses to the interpolation of
the others in 5 of 18 runs instead of 7.  The nodes move by at most 1.9-5.0 mm; every tet keeps
68-124 % of its volume.  With the speaker's palate the deepest penetration falls from 2.84 to 2.20 mm
(/ta/ 009) and from 3.76 to 2.11 mm (/ka/ 006), and every frame with a sensor within 1 mm of the
palate still shows the tongue touching it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse.linalg as spla

from tonguevis._logging import logger
from tonguevis.errors import SimulationError
from tonguevis.mesh.tetmesh import TetMesh
from tonguevis.sim.model import TongueModel

#: A full bend that would leave a tet less than this share of its volume (or turn it inside out) is
#: taken only part of the way (:func:`bend_fraction`): the rest sensors ask for a shape the mesh cannot
#: take smoothly (rest sensors far from their nodes: 12 mm on the Carstens rticulate file, 7.6 mm on
#: the Haskins sentence with another rest).  The bends the shared Opti-Speech and Haskins recordings
#: ask for keep every tet at 68 % or more.
MIN_VOLUME_RATIO = 0.5


def tet_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """(T,) signed volumes (m³) of the tets ``tets`` (T, 4) of ``points`` (n, 3)."""
    p = np.asarray(points, dtype=np.float64)
    a, b, c = (p[tets[:, k]] - p[tets[:, 0]] for k in (1, 2, 3))
    return np.einsum("ij,ij->i", np.cross(a, b), c) / 6.0


def fit_rest_shape(model: TongueModel, nodes: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """(n, 3) m: the static displacement of ``model`` that puts each node of ``nodes`` (S,) on its rest
    sensor ``rest`` (S, 3, m, the model's frame), the anchors held (linear elasticity, the model's K)."""
    nodes = np.asarray(nodes, dtype=np.int64)
    n = model.mesh.n_nodes
    u = np.zeros(3 * n)
    prescribed = np.zeros(3 * n, dtype=bool)
    anchors = np.asarray(model.anchors, dtype=np.int64)
    prescribed[(3 * anchors[:, None] + np.arange(3)).ravel()] = True
    sensor_dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    u[sensor_dofs] = (np.asarray(rest, dtype=np.float64) - model.mesh.points[nodes]).ravel()
    prescribed[sensor_dofs] = True
    free = ~prescribed
    stiffness = model.stiffness.tocsr()
    rhs = -(stiffness[free][:, prescribed] @ u[prescribed])
    u[free] = spla.spsolve(stiffness[free][:, free].tocsc(), rhs)
    return u.reshape(n, 3)


class RestFittedModel(TongueModel):
    """``unfitted`` (a tongue model, placed in a speaker or not) with its rest shape moved by
    ``displacement`` (n, 3, m): same tets, node ids, landmarks, anchors and material; its own modes.

    ``placement`` is the unfitted model's (so the generic palate is carried into its frame as before);
    ``rest_fit`` holds the fit's figures (mm).  Not a placement of the shipped tongue: two recordings'
    rest-fitted tongues are different bodies with different modes, so comparing or morphing across them
    carries one's deformation through its modal shapes fitted onto the other's modes
    (:func:`tonguevis.sim.placement.modal_transfer`), not by sharing modal coordinates.
    """

    def __init__(self, unfitted: TongueModel, displacement: np.ndarray | None, info: dict[str, Any] | None = None,
                 points: np.ndarray | None = None):
        self.unfitted = unfitted
        self.placement = getattr(unfitted, "placement", None)
        self.rest_fit = dict(info or {})
        meta = {**unfitted.mesh.metadata, "rest_fit": self.rest_fit}
        # ``points`` (n, 3) given: the fitted rest shape as saved, bit for bit (its modes' cache key is the same)
        fitted = np.asarray(points, dtype=np.float64) if points is not None else \
            unfitted.mesh.points + np.asarray(displacement, dtype=np.float64)
        mesh = TetMesh(fitted, unfitted.mesh.tets, metadata=meta)
        super().__init__(mesh, unfitted.landmarks, unfitted.material)
        self._dorsal = np.asarray(unfitted.dorsal_nodes)

    @property
    def dorsal_nodes(self) -> np.ndarray:
        """The unfitted model's: which nodes a sensor may sit on is the tongue's anatomy, not its rest shape."""
        return self._dorsal

    def __repr__(self) -> str:
        return f"RestFittedModel(moved up to {self.rest_fit.get('moved_max_mm', float('nan')):.2f} mm, {self.unfitted!r})"


def rest_fitted_model_of(model: Any) -> "RestFittedModel | None":
    """The :class:`RestFittedModel` ``model`` is (or, a sensor-patch or volume copy, is built on), else None."""
    for candidate in (model, getattr(model, "base_model", None)):
        if isinstance(candidate, RestFittedModel):
            return candidate
    return None


def bend_fraction(points: np.ndarray, tets: np.ndarray, u: np.ndarray,
                  min_ratio: float = MIN_VOLUME_RATIO, steps: int = 40) -> float:
    """The largest a in [0, 1] such that every tet of ``points`` + a' ``u`` keeps at least ``min_ratio``
    of its volume for every a' <= a (points, u: (n, 3) m; tets (T, 4)).

    A tet's volume is a cubic in a, so the first crossing is bracketed on a grid of ``steps`` and then
    bisected (to 1e-6)."""
    rest = tet_volumes(points, tets)

    def worst(a: float) -> float:
        return float(np.min(tet_volumes(points + a * u, tets) / rest))

    grid = np.linspace(0.0, 1.0, steps + 1)
    low = 0.0
    for a in grid[1:]:
        if worst(a) < min_ratio:
            high = a
            break
        low = a
    else:
        return 1.0
    while high - low > 1e-6:
        mid = 0.5 * (low + high)
        low, high = (mid, high) if worst(mid) >= min_ratio else (low, mid)
    return low


def rest_fitted(model: TongueModel, nodes: np.ndarray, rest: np.ndarray, file=None) -> RestFittedModel:
    """``model`` bent so its sensor nodes ``nodes`` (S,) sit on the rest sensors ``rest`` (S, 3, m).

    Where the full bend would leave a tet under :data:`MIN_VOLUME_RATIO` of its volume, the bend goes
    only that far (``rest_fit["fraction"]`` < 1, the sensors still ``sensors_after_rms_mm`` off their
    nodes; warned about naming ``file``).  SimulationError naming ``file`` when the static solve fails."""
    u = fit_rest_shape(model, nodes, rest)
    if not np.all(np.isfinite(u)):
        raise SimulationError("the tongue's static response to its rest sensors could not be solved (the mesh's "
                              "stiffness is singular with the anchors held): simulate without fitting the rest shape",
                              file)
    before = np.linalg.norm(np.asarray(rest) - model.mesh.points[np.asarray(nodes)], axis=1)
    fraction = bend_fraction(model.mesh.points, model.mesh.tets, u)
    u = fraction * u
    after = (1.0 - fraction) * before
    if fraction < 1.0:
        logger.warning(
            "%s: the rest sensors lie up to %.1f mm from their nodes; bending the tongue all the way onto them would "
            "crush its tets, so it is bent %.0f %% of the way (every tet keeps %.0f %% of its volume or more) and the "
            "sensors stay %.2f mm RMS off their nodes", file or "the recording", 1e3 * before.max(), 100 * fraction,
            100 * MIN_VOLUME_RATIO, 1e3 * np.sqrt(np.mean(after ** 2)))
    ratio = tet_volumes(model.mesh.points + u, model.mesh.tets) / tet_volumes(model.mesh.points, model.mesh.tets)
    moved = np.linalg.norm(u, axis=1)
    info = {"fraction": float(fraction),
            "moved_max_mm": float(1e3 * moved.max()), "moved_rms_mm": float(1e3 * np.sqrt(np.mean(moved ** 2))),
            "sensors_before_rms_mm": float(1e3 * np.sqrt(np.mean(before ** 2))),
            "sensors_before_max_mm": float(1e3 * before.max()),
            "sensors_after_rms_mm": float(1e3 * np.sqrt(np.mean(after ** 2))),
            "tet_volume_ratio_min": float(ratio.min()), "tet_volume_ratio_max": float(ratio.max()),
            "volume_change_percent": float(100 * (np.sum(tet_volumes(model.mesh.points + u, model.mesh.tets))
                                                  / np.sum(tet_volumes(model.mesh.points, model.mesh.tets)) - 1))}
    return RestFittedModel(model, u, info)
