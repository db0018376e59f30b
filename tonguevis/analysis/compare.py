"""Two motions side by side: which frames match, and how far apart the two tongues are.

People compare: a patient with a reference speaker, before with after
therapy, one speaker's /ta/ with another's, one recording under two models.
Speakers differ in rate, so frames are matched per production by normalised
time (0 at the consonant release opening it, 1 at the next release): the
k-th production of one recording is laid over the k-th of the other, so
syllables line up whatever their durations.  On absolute time instead,
frames are matched by their times.

Both motions are on one tongue model: in the model frame (each recording aligned
onto it) or each placed in its own speaker, B's deformation then carried onto A's
placement (:func:`tonguevis.sim.placement.carried`), so the per-node distance
between the two shapes at matched frames is the difference a clinician looks at.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tonguevis.errors import TonguevisError


@dataclass
class FrameMatch:
    """Matched frames of two motions.

    frames_a, frames_b : (K,) int frame indices; phase : (K,) the normalised
    time within the production (production mode), or the time in seconds
    (absolute mode); production : (K,) the production number (1-based), 0 in
    absolute mode; mode : "production" or "absolute".
    """

    frames_a: np.ndarray
    frames_b: np.ndarray
    phase: np.ndarray
    production: np.ndarray
    mode: str

    def __len__(self) -> int:
        return int(len(self.frames_a))

    def partner(self, frame_a: int) -> int | None:
        """The frame of B shown with frame ``frame_a`` of A (None when A's frame is outside every pair)."""
        hits = np.flatnonzero(self.frames_a == frame_a)
        return int(self.frames_b[hits[0]]) if len(hits) else None


def match_frames(times_a: np.ndarray, times_b: np.ndarray, productions_a=None, productions_b=None,
                 mode: str = "production") -> FrameMatch:
    """Pair the frames of A with frames of B.

    times_a, times_b : (F_a,), (F_b,) frame times in seconds.
    productions_a, productions_b : sequences of objects with ``start`` and
    ``end`` (seconds), e.g. :class:`tonguevis.preprocess.productions.ProductionTable`;
    needed for ``mode="production"`` (pairs the first min(P_a, P_b) productions).
    In production mode every frame of A inside a paired production gets the
    frame of B at the same normalised time; in absolute mode every frame of A
    gets B's frame nearest in time (frames of A past B's end are left out).
    """
    times_a = np.asarray(times_a, dtype=np.float64)
    times_b = np.asarray(times_b, dtype=np.float64)
    if mode == "absolute":
        inside = (times_a >= times_b[0] - 1e-9) & (times_a <= times_b[-1] + 1e-9)
        fa = np.flatnonzero(inside)
        fb = _nearest(times_b, times_a[fa])
        return FrameMatch(fa, fb, times_a[fa], np.zeros(len(fa), dtype=np.int64), "absolute")
    if mode != "production":
        raise TonguevisError(f"compare mode must be 'production' or 'absolute', got {mode!r}")
    pa, pb = list(productions_a or []), list(productions_b or [])
    if not pa or not pb:
        raise TonguevisError("matching by production needs productions in both recordings "
                             f"(found {len(pa)} and {len(pb)}); compare on absolute time instead")
    frames_a, frames_b, phase, number = [], [], [], []
    for k, (a, b) in enumerate(zip(pa, pb), start=1):
        fa = np.flatnonzero((times_a >= a.start) & (times_a <= a.end))
        if len(fa) == 0 or a.end <= a.start or b.end <= b.start:
            continue
        u = (times_a[fa] - a.start) / (a.end - a.start)
        fb = _nearest(times_b, b.start + u * (b.end - b.start))
        frames_a.append(fa)
        frames_b.append(fb)
        phase.append(u)
        number.append(np.full(len(fa), k))
    if not frames_a:
        raise TonguevisError("no production of the first recording has frames to match")
    return FrameMatch(np.concatenate(frames_a), np.concatenate(frames_b), np.concatenate(phase),
                      np.concatenate(number), "production")


def node_distances(motion_a, motion_b, match: FrameMatch, frames: slice | np.ndarray | None = None) -> np.ndarray:
    """(K', n) distance in metres between the two tongues' nodes at matched frames.

    Both motions must share the mesh (the same model); ``frames`` selects
    among the K pairs (default all: O(K × nodes) memory).
    """
    mesh_a, mesh_b = motion_a.model.mesh, motion_b.model.mesh
    if mesh_a.n_nodes != mesh_b.n_nodes or not np.allclose(mesh_a.points, mesh_b.points):
        raise TonguevisError("the two motions are on different tongue meshes: a per-node difference needs the "
                             "same model for both")
    sel = np.arange(len(match)) if frames is None else np.arange(len(match))[frames]
    ua = motion_a.displacements(match.frames_a[sel])
    ub = motion_b.displacements(match.frames_b[sel])
    return np.linalg.norm(ua - ub, axis=2)


def _nearest(times: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Index of the sorted ``times`` nearest each of ``t`` (clipped)."""
    i = np.clip(np.searchsorted(times, t), 1, len(times) - 1)
    return np.where(np.abs(times[i - 1] - t) <= np.abs(times[i] - t), i - 1, i)


def production_time_map(productions_a, productions_b) -> tuple[np.ndarray, np.ndarray]:
    """Knots of the piecewise-linear map from A's clock to B's that lines productions up.

    The k-th production of A (start, end) is mapped onto the k-th of B, so within a
    production normalised time is kept (as :func:`match_frames` pairs frames); between
    two productions time is stretched the same way, so the map is continuous and
    increasing.  Returns (knots_a, knots_b), (K,) seconds, strictly increasing (a knot
    that would break the order, e.g. overlapping productions, is left out).
    """
    pairs = []
    for a, b in zip(list(productions_a or []), list(productions_b or [])):
        if a.end > a.start and b.end > b.start:
            pairs += [(float(a.start), float(b.start)), (float(a.end), float(b.end))]
    knots_a, knots_b = [], []
    for ta, tb in pairs:
        if not knots_a or (ta > knots_a[-1] and tb > knots_b[-1]):
            knots_a.append(ta)
            knots_b.append(tb)
    if len(knots_a) < 2:
        raise TonguevisError("lining recordings up by production needs a production in both "
                             f"(found {len(list(productions_a or []))} and {len(list(productions_b or []))}); "
                             "compare on absolute time instead")
    return np.asarray(knots_a), np.asarray(knots_b)


@dataclass
class Comparison:
    """Two simulated recordings compared: which moment of B goes with each moment of A,
    and how far apart the two tongues are there.

    motion_a, motion_b : the two Motions (any models; a per-node difference needs the same mesh).
    mode : "production" (productions lined up by normalised time, see
        :func:`production_time_map`; before A's first and after its last production B
        runs at A's pace from the nearest knot) or "absolute" (the same time on both clocks).
    productions_a, productions_b : objects with ``start``/``end`` seconds (production mode).
    """

    motion_a: object
    motion_b: object
    mode: str = "production"
    productions_a: object = None
    productions_b: object = None

    def __post_init__(self) -> None:
        if self.mode not in ("production", "absolute"):
            raise TonguevisError(f"compare mode must be 'production' or 'absolute', got {self.mode!r}")
        self._knots = (production_time_map(self.productions_a, self.productions_b)
                       if self.mode == "production" else None)
        # In the speaker frame each recording places the tongue in its own speaker: B's deformation is
        # compared on A's placement (tonguevis.sim.placement.carried), node by node.
        from tonguevis.sim.patches import global_part
        from tonguevis.sim.placement import carried, same_source

        model_a = global_part(self.motion_a)[0]
        if not self.same_mesh and same_source(model_a, self.motion_b.model):
            self.motion_b = carried(self.motion_b, model_a)

    @property
    def same_mesh(self) -> bool:
        """True when both motions are on one tongue mesh (so a per-node difference means something)."""
        a, b = self.motion_a.model.mesh, self.motion_b.model.mesh
        return a.n_nodes == b.n_nodes and bool(np.allclose(a.points, b.points))

    def time_b(self, t_a) -> np.ndarray | float:
        """The time on B's clock (seconds, inside B's motion) shown with time ``t_a`` of A (scalar or array)."""
        t = np.asarray(t_a, dtype=np.float64)
        if self._knots is None:
            out = t.copy()
        else:
            ka, kb = self._knots
            out = np.interp(t, ka, kb)
            out = np.where(t < ka[0], kb[0] + (t - ka[0]), out)
            out = np.where(t > ka[-1], kb[-1] + (t - ka[-1]), out)
        times = self.motion_b.times
        out = np.clip(out, times[0], times[-1])
        return float(out) if out.ndim == 0 else out

    def frame_b(self, t_a: float) -> int:
        """B's frame shown with time ``t_a`` of A."""
        times = self.motion_b.times
        return int(_nearest(times, np.atleast_1d(self.time_b(t_a)))[0])

    def phase(self, t_a: float) -> tuple[int, float] | None:
        """(production number, 1-based; normalised time in it) of A's time ``t_a``, or None outside them
        (and in absolute mode)."""
        if self._knots is None:
            return None
        for k, p in enumerate(list(self.productions_a or []), start=1):
            if p.start <= t_a <= p.end and p.end > p.start:
                return k, float((t_a - p.start) / (p.end - p.start))
        return None

    def productions_in_b(self) -> int:
        """How many productions B has (production k of A is shown with production k of B while k <= this)."""
        return len(list(self.productions_b or []))

    def difference(self, frame_a: int, frame_b: int, nodes: np.ndarray | None = None) -> np.ndarray:
        """(k,) distance in metres between node i of A at ``frame_a`` and node i of B at ``frame_b``
        (``nodes``: the node ids, default every node), both in the model frame."""
        if not self.same_mesh:
            raise TonguevisError("the two recordings are on different tongue meshes: a per-node difference needs "
                                 "the same model for both")
        ua = self.motion_a.displacements(np.array([frame_a]), nodes=nodes)[0]
        ub = self.motion_b.displacements(np.array([frame_b]), nodes=nodes)[0]
        return np.linalg.norm(ua - ub, axis=1)
