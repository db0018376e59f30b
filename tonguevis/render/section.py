"""The midsagittal section of a triangle surface: the segments where a plane y = const cuts it (NumPy only)."""

from __future__ import annotations

import numpy as np


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
