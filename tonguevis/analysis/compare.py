"""Two motions side by side: which frames match, and how far apart the two tongues are.

People compare: a patient with a reference speaker, before with after
therapy, one speaker's /ta/ with another's, one recording under two models.
Speakers differ in rate, so frames are matched per production by normalised
time (0 at the consonant release opening it, 1 at the next release): the
k-th production of one recording is laid over the k-th of the other, so
syllables line up whatever their durations.  On absolute time instead,
frames are matched by their times.

Both motions are already in the model frame (each recording aligned onto the
model), so when they share a model the per-node distance between the two
shapes at matched frames is the difference a clinician looks at.
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
