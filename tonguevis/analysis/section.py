"""The tongue against the palate in the mid-plane: the midsagittal section of a surface and the dorsal midline's
distance to the palate (what the midsagittal views and the Palate tab draw, and what the analyses can use).
NumPy only."""

from __future__ import annotations

import numpy as np

#: m: nodes within this of the tongue's mid-plane make its midline.
MIDLINE_BAND = 2e-3
#: mm: the midline's bins along the tongue, behind its tip.
MIDLINE_BIN_MM = 2.0


def plane_section(points: np.ndarray, faces: np.ndarray, y: float) -> np.ndarray:
    """(n, 2, 2) segments (x, z), in the points' unit, where the plane ``y`` cuts the triangles ``faces``.

    points : (N, 3); faces : (F, 3) indices.  Each triangle with corners on both sides of the
    plane gives one segment between the two points where its edges cross it (vectorised over
    every triangle: a frame's section of the tongue costs well under a millisecond).  A
    triangle touching the plane at a corner only gives nothing.
    """
    p = np.asarray(points, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    side = p[:, 1] - y
    s = side[f]  # (F, 3)
    above = s > 0
    crossing = above.any(axis=1) & ~above.all(axis=1)
    f, s = f[crossing], s[crossing]
    ends = np.empty((len(f), 2, 2))
    count = np.zeros(len(f), dtype=np.int64)
    rows = np.arange(len(f))
    for i, j in ((0, 1), (1, 2), (2, 0)):
        a, b = s[:, i], s[:, j]
        cut = (a > 0) != (b > 0)
        r = rows[cut & (count < 2)]
        t = (a[r] / (a[r] - b[r]))[:, None]
        xz = p[f[r, i]][:, [0, 2]] + t * (p[f[r, j]][:, [0, 2]] - p[f[r, i]][:, [0, 2]])
        ends[r, count[r]] = xz
        count[r] += 1
    return ends[count == 2]


class MidlineProfile:
    """The tongue's dorsal midline: nodes within :data:`MIDLINE_BAND` of its mid-plane, by distance behind the tip.

    ``position_mm`` (b,): centre of each :data:`MIDLINE_BIN_MM` bin, mm behind the tongue tip
    at rest (along x); ``nodes`` the mesh nodes, ``bin_of`` each node's bin.
    """

    def __init__(self, model):
        points = np.asarray(model.mesh.points, dtype=np.float64)
        dorsal = np.asarray(getattr(model, "dorsal_nodes", np.arange(len(points))))
        mid = float(np.median(points[:, 1]))
        band = MIDLINE_BAND
        nodes = dorsal[np.abs(points[dorsal, 1] - mid) < band]
        while len(nodes) < 8 and band < 4 * MIDLINE_BAND:  # a coarse mesh: widen the band
            band *= 1.5
            nodes = dorsal[np.abs(points[dorsal, 1] - mid) < band]
        near_mid = np.abs(points[:, 1] - mid) < band
        tip = float(points[near_mid, 0].max()) if near_mid.any() else float(points[:, 0].max())
        behind = 1e3 * (tip - points[nodes, 0])
        order = np.argsort(behind, kind="stable")
        self.nodes = nodes[order]
        bins = np.floor(behind[order] / MIDLINE_BIN_MM).astype(np.int64)
        self.bins, self.bin_of = np.unique(bins, return_inverse=True)
        self.bin_of = self.bin_of.ravel()
        self.position_mm = (self.bins + 0.5) * MIDLINE_BIN_MM
        self.band_mm = 1e3 * band

    def distance_range(self, palate, motion, most_frames: int = 2000) -> tuple[float, float]:
        """(smallest, largest) distance (mm) of the midline to ``palate`` (as :meth:`distances`) over ``motion``
        in the head frame (at most ``most_frames`` frames spread evenly over it): the range a plot of every
        frame needs; (NaN, NaN) when no palate lies above the midline."""
        from tonguevis.sim.reference import jaw_moves

        n = motion.n_frames
        picked = np.unique(np.linspace(0, n - 1, min(n, most_frames)).round().astype(np.int64))
        rest = np.asarray(motion.model.mesh.points, dtype=np.float64)[self.nodes]
        moves = jaw_moves(motion)
        low, high = np.inf, -np.inf
        for frames, u in motion.iter_displacements(frames=picked, nodes=self.nodes):
            points = (rest[None] + u + (np.asarray(motion.jaw_offset)[frames, None] if moves else 0.0)).reshape(-1, 3)
            if hasattr(palate, "clearance_mm"):
                gap = np.asarray(palate.clearance_mm(points), dtype=np.float64)
            else:
                gap = 1e3 * palate.clearance(points)[0]
            gap = gap[np.isfinite(gap)]
            if gap.size:
                low, high = min(low, float(gap.min())), max(high, float(gap.max()))
        return (low, high) if np.isfinite(low) else (float("nan"), float("nan"))

    def distances(self, palate, head_points: np.ndarray) -> np.ndarray:
        """(b,) mm: the smallest distance to ``palate`` (a :class:`~tonguevis.palate.PalateSurface`, or anything
        with ``clearance_mm(points)``: the app's shown palate) in each bin (NaN where no palate lies above);
        ``head_points`` (n, 3) m, the tongue's nodes in the palate's frame."""
        points = np.asarray(head_points, dtype=np.float64)[self.nodes]
        if hasattr(palate, "clearance_mm"):
            gap = np.asarray(palate.clearance_mm(points), dtype=np.float64)
        else:
            gap = 1e3 * palate.clearance(points)[0]
        out = np.full(len(self.bins), np.inf)
        np.minimum.at(out, self.bin_of, np.where(np.isfinite(gap), gap, np.inf))
        return np.where(np.isfinite(out), out, np.nan)

    def closest_approach(self, motion, chunk: int = 512) -> tuple[float, float, float] | None:
        """Where the dorsal midline comes closest to the palate ``motion`` was simulated against, over the whole
        motion: (distance mm, negative inside; mm behind the tongue tip; time s), against the palate of each frame
        (:meth:`~tonguevis.sim.motion.Motion.palate_at`: the velum lifted as simulated).  None without a palate or
        where no palate lies above the midline."""
        palate = getattr(motion, "palate", None)
        if palate is None:
            return None
        rest = np.asarray(motion.model.mesh.points, dtype=np.float64)[self.nodes]
        jaw = motion.jaw_offset if motion.jaw_offset is not None else np.zeros((motion.n_frames, 3))
        lift = motion.velum_lift
        best = (np.inf, 0, 0)
        for frames, u in motion.iter_displacements(chunk=chunk, nodes=self.nodes):
            frames = np.asarray(frames)
            points = rest[None] + u + np.asarray(jaw)[frames][:, None]
            amounts = None if lift is None else np.repeat(np.asarray(lift)[frames], len(self.nodes))
            gap = palate.clearance(points.reshape(-1, 3), lift=amounts)[0].reshape(len(frames), -1)
            gap = np.where(np.isfinite(gap), gap, np.inf)
            k = int(np.argmin(gap))
            f, n = np.unravel_index(k, gap.shape)
            if gap[f, n] < best[0]:
                best = (float(gap[f, n]), int(frames[f]), int(n))
        if not np.isfinite(best[0]):
            return None
        gap, frame, node = best
        return 1e3 * gap, float(self.position_mm[self.bin_of[node]]), float(motion.times[frame])
