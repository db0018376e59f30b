"""Morphing between two deformed shapes (§6.4, Figs. 15-16).

Which end is which: the blend is

    q(t) = (1 − t) q_source + t q_target,   0 ≤ t ≤ 1,

so **t = 0 is the source** and **t = 1 the target** (the paper writes the
weights the other way round).  Only the linear part is blended; the blend is
then warped in the direct form ũ_i = R̃((W q)_i) (Φ q)_i, which depends on q
alone (no history), so both ends are reproduced exactly.

Colour: each element E gets the difference of eq. (14) between the two ends,
e_E = ‖ũ_E^source − ũ_E^target‖² / V_E (the 12-vector of its four nodes'
warped displacements, m² / m³), and the colour is its empirical CDF value, so
that the colours spread evenly over the mesh (the paper "linearises the
cumulative distribution function").  Low difference maps to blue, high to red.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from tonguevis.errors import TonguevisError
from tonguevis.mesh.tetmesh import signed_tet_volumes


class MorphError(TonguevisError):
    """A morph asked between incompatible shapes."""


#: Element differences a morph can colour by: eq. (14) as the paper writes it, or
#: the mean squared distance of the element's nodes, which does not depend on
#: the element's size (eq. 14 divides by V_E, so on a mesh of uneven tets the
#: small ones stand out whatever the shapes do).
DIFFERENCES = ("eq14", "node_mean")


def element_difference(points: np.ndarray, tets: np.ndarray, u_a: np.ndarray, u_b: np.ndarray,
                       kind: str = "eq14") -> np.ndarray:
    """(E,) difference of two displacements per element.

    "eq14": ‖u_a,E − u_b,E‖² / V_E over each tet's 4 nodes (the 12-vector), in 1/m;
    "node_mean": the mean over the 4 nodes of |u_a − u_b|², in m².
    points (n, 3) rest positions (m); tets (E, 4); u_a, u_b (n, 3) displacements (m).
    """
    diff2 = np.einsum("ij,ij->i", u_a - u_b, u_a - u_b)
    if kind == "eq14":
        return diff2[tets].sum(axis=1) / np.abs(signed_tet_volumes(points, tets))
    if kind == "node_mean":
        return diff2[tets].mean(axis=1)
    raise MorphError(f"unknown element difference {kind!r}; choose one of {', '.join(DIFFERENCES)}")


def cdf_colour(values: np.ndarray) -> np.ndarray:
    """(N,) empirical CDF of ``values`` in (0, 1): (rank − ½)/N, ties sharing their mean rank.

    For distinct values the result is exactly {½/N, 1½/N, ...}: uniform, in the
    same order as the values.
    """
    values = np.asarray(values, dtype=np.float64).ravel()
    n = values.size
    if n == 0:
        return values.copy()
    order = np.argsort(values, kind="stable")
    ordered = values[order]
    # Tie groups: runs of equal values in sorted order share the mean of their 1-based ranks.
    starts = np.flatnonzero(np.concatenate([[True], ordered[1:] != ordered[:-1]]))
    ends = np.append(starts[1:], n)  # exclusive
    mean_rank = 0.5 * (starts + 1 + ends)  # mean of ranks starts+1 .. ends
    ranks = np.empty(n)
    ranks[order] = np.repeat(mean_rank, ends - starts)
    return (ranks - 0.5) / n


def play_schedule(n_frames: int, back: bool = True) -> np.ndarray:
    """Blend parameters for playing: ``n_frames`` from 0 (source) to 1 (target), then back if ``back``."""
    if n_frames < 2:
        raise MorphError(f"a morph needs at least 2 frames, got {n_frames}")
    forward = np.linspace(0.0, 1.0, n_frames)
    return np.concatenate([forward, forward[-2::-1]]) if back else forward


class Morph:
    """Morph of one model from ``q_source`` (t = 0) to ``q_target`` (t = 1).

    model : the :class:`~tonguevis.sim.TongueModel` both shapes live on.
    q_source, q_target : (m,) modal displacements (m·kg^½) on its m-mode basis.
    warping : warp the blend (the paper); False blends the linear shapes.
    """

    def __init__(self, model, q_source: np.ndarray, q_target: np.ndarray, warping: bool = True,
                 labels: tuple[str, str] = ("source", "target"), difference: str = "eq14"):
        if difference not in DIFFERENCES:
            raise MorphError(f"unknown element difference {difference!r}; choose one of {', '.join(DIFFERENCES)}")
        self.difference = difference
        q_source = np.asarray(q_source, dtype=np.float64).ravel()
        q_target = np.asarray(q_target, dtype=np.float64).ravel()
        if q_source.shape != q_target.shape:
            raise MorphError(f"source has {q_source.size} modes but target {q_target.size}")
        if not (np.all(np.isfinite(q_source)) and np.all(np.isfinite(q_target))):
            raise MorphError("modal displacements must be finite")
        self.model = model
        self.q_source, self.q_target = q_source, q_target
        self.warping = bool(warping)
        self.labels = labels
        basis = model.basis(q_source.size)
        n = model.mesh.n_nodes
        ends = np.stack([q_source, q_target], axis=1)  # (m, 2)
        lin = (basis.phi @ ends).T.reshape(2, n, 3)
        if self.warping:
            rot = (model.rotation_matrix(basis) @ ends).T.reshape(2, n, 3)
        else:
            rot = np.zeros_like(lin)
        self._lin, self._rot = lin, rot
        self._kernel = None

    # ------------------------------------------------------------------ the two ends
    def blend(self, t: float) -> np.ndarray:
        """(m,) q(t) = (1 − t) q_source + t q_target."""
        return (1.0 - t) * self.q_source + t * self.q_target

    @cached_property
    def source_displacement(self) -> np.ndarray:
        """(n, 3) warped displacement of the source (m)."""
        return self.displacements([0.0])[0]

    @cached_property
    def target_displacement(self) -> np.ndarray:
        """(n, 3) warped displacement of the target (m)."""
        return self.displacements([1.0])[0]

    @cached_property
    def element_difference(self) -> np.ndarray:
        """(E,) difference between source and target: eq. (14) in 1/m (default) or node_mean in m²."""
        mesh = self.model.mesh
        return element_difference(mesh.points, mesh.tets, self.source_displacement, self.target_displacement,
                                  self.difference)

    @cached_property
    def element_colour(self) -> np.ndarray:
        """(E,) colour value in (0, 1): the empirical CDF of :attr:`element_difference`."""
        return cdf_colour(self.element_difference)

    @property
    def difference_unit(self) -> str:
        return "1/m" if self.difference == "eq14" else "m²"

    def colour_legend(self, quantiles=(0.0, 0.25, 0.5, 0.75, 1.0)) -> list[tuple[float, float]]:
        """(colour value, difference in :attr:`difference_unit`) pairs for a legend, at those quantiles."""
        return [(float(qn), float(np.quantile(self.element_difference, qn))) for qn in quantiles]

    # ------------------------------------------------------------------ frames
    def displacements(self, ts, dtype=np.float64) -> np.ndarray:
        """(T, n, 3) displacement (m) of the blends at parameters ``ts`` (T,), each in [0, 1]."""
        ts = np.atleast_1d(np.asarray(ts, dtype=np.float64))
        if np.any((ts < 0) | (ts > 1)) or not np.all(np.isfinite(ts)):
            raise MorphError(f"blend parameters must lie in [0, 1], got {ts.min():.3g}..{ts.max():.3g}")
        if not self.warping:
            s = 1.0 - ts
            return (s[:, None, None] * self._lin[0] + ts[:, None, None] * self._lin[1]).astype(dtype)
        if self._kernel is None:
            from tonguevis.analysis.morph_kernels import MorphKernel

            self._kernel = MorphKernel(self._lin[0], self._lin[1], self._rot[0], self._rot[1])
        return self._kernel.frames(ts, dtype=dtype).copy()

    def displacement(self, t: float) -> np.ndarray:
        """(n, 3) displacement (m) at blend parameter t."""
        return self.displacements([t])[0]

    def points(self, t: float) -> np.ndarray:
        """(n, 3) deformed node positions (m) at blend parameter t."""
        return self.model.mesh.points + self.displacement(t)


def morph_displacements_reference(model, q_source, q_target, ts, warping: bool = True) -> np.ndarray:
    """(T, n, 3) plain reference: blend q, then the model's own reconstruction, one t at a time."""
    return np.stack([
        model.displacement((1.0 - t) * np.asarray(q_source) + t * np.asarray(q_target), warping=warping)
        for t in np.atleast_1d(ts)
    ])


def same_model(a, b) -> bool:
    """Whether two models share mesh, anchors, material (the modal basis key), so q's are comparable."""
    if a is b:
        return True
    if a.mesh.n_nodes != b.mesh.n_nodes or a.mesh.n_tets != b.mesh.n_tets:
        return False
    return a.basis_key(1) == b.basis_key(1)


def morph_between(source_motion, source_time: float, target_motion, target_time: float,
                  difference: str = "eq14") -> Morph:
    """A :class:`Morph` from the frame of ``source_motion`` nearest ``source_time`` (s)
    to the frame of ``target_motion`` nearest ``target_time``; both motions on the same model."""
    from tonguevis.sim.patches import global_part
    from tonguevis.sim.placement import modal_scale, source_model

    # Two speakers (or frames) place the same tongue differently: the target's shape is carried onto the
    # source's placement through the model they share (its strain field, in the source's size).
    if global_part(source_motion)[1].shape[1] != global_part(target_motion)[1].shape[1]:
        raise MorphError(f"source motion has {global_part(source_motion)[1].shape[1]} modes, target "
                         f"{global_part(target_motion)[1].shape[1]}; simulate both with the same number")
    rescale = 1.0
    transfer = None
    if not same_model(source_motion.model, target_motion.model):
        a, b = global_part(source_motion)[0], global_part(target_motion)[0]
        if not same_model(source_model(a), source_model(b)):
            raise MorphError("source and target motions are on different tongue models (mesh, anchors or "
                             "material differ); morphing needs the same model")
        from tonguevis.sim.rest_fit import rest_fitted_model_of

        if rest_fitted_model_of(a) is None and rest_fitted_model_of(b) is None:
            rescale = modal_scale(a) / modal_scale(b)
        else:  # rest shapes fitted to two speakers: the target's modal shapes fitted onto the source's modes
            from tonguevis.sim.placement import modal_transfer, placement_between

            move = placement_between(b, a)
            n_modes = global_part(target_motion)[1].shape[1]
            transfer = modal_transfer(b, a, move.scale * move.rotation, n_modes)[0]

    if source_motion.warping != target_motion.warping:
        raise MorphError("one motion is warped and the other linear")
    for motion, t, what in ((source_motion, source_time, "source"), (target_motion, target_time, "target")):
        half = 0.5 * float(np.median(np.diff(motion.times))) if motion.n_frames > 1 else 0.0
        if not motion.times[0] - half <= t <= motion.times[-1] + half:
            raise MorphError(f"{what} time {t:.3f} s is outside its motion ({motion.times[0]:.3f}-"
                             f"{motion.times[-1]:.3f} s)")
    i, j = source_motion.frame_at(source_time), target_motion.frame_at(target_time)
    # Use the source's model for both: the target's q lives on an identical basis.  Sensor patches
    # (tonguevis.sim.patches) belong to one recording's sensors: the morph is between the modes.
    from tonguevis.sim.patches import global_part

    model, q_source = global_part(source_motion)
    q_target = rescale * global_part(target_motion)[1]
    if transfer is not None:
        q_target = q_target @ transfer.T
    morph = Morph(model, q_source[i], q_target[j], warping=source_motion.warping, difference=difference)
    morph.source_frame, morph.target_frame = i, j
    return morph
