"""Per-frame figures of a whole motion from q, chunk by chunk, in bounded memory.

A motion's state is its modal displacement q (F, m): 100 numbers a frame.  The
full-mesh displacement is F × n × 3 values, which a long recording cannot keep
(30 minutes at 100 Hz on 1,802 nodes: 7.8 GB in float64).  What a simulation
reports per frame (volume change, the largest node displacement behind the
far-field amplification, penetration into the palate and contact area) needs
one frame's displacement at a time, so :func:`frame_figures` reconstructs
:data:`~tonguevis.sim.model.CHUNK_FRAMES` frames at once
(:meth:`TongueModel.displacements`, vectorised over the chunk), measures them
and drops them: the working set is a few tens of MB whatever the length.  A
test proves the figures equal to those of the whole array.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.sim.model import CHUNK_FRAMES


@dataclass
class FrameFigures:
    """Per-frame figures of a motion (F frames).

    volume_change : (F,) (V - V_rest) / V_rest of the (warped) mesh.
    largest_displacement : (F,) metres, the largest node displacement.
    penetration : (F,) metres, the deepest candidate node inside the palate, or None without a palate.
    contact_area : (F,) m², the surface within ``contact.TOUCH`` of the palate, or None.
    """

    volume_change: np.ndarray
    largest_displacement: np.ndarray
    penetration: np.ndarray | None = None
    contact_area: np.ndarray | None = None


@dataclass
class ContactProbe:
    """What measuring contact needs, in the model frame.

    points : (n, 3) rest node positions, m; candidates : (k,) nodes that can meet the palate;
    palate : a PalateSurface; jaw_offset : (F, 3) m, carries the tongue into the palate's frame;
    faces : (f, 3) surface triangles; conflicts : (c, 2) int (frame, sensor index) where a
    sensor lies above the palate; near : (k, S) bool, candidates left to each sensor in its
    conflicts (not counted in the penetration).
    """

    points: np.ndarray
    candidates: np.ndarray
    palate: object
    jaw_offset: np.ndarray
    faces: np.ndarray
    conflicts: np.ndarray
    near: np.ndarray

    def exclude(self, start: int, stop: int) -> np.ndarray:
        """(stop - start, k) bool: the candidates not counted in frames start..stop-1."""
        out = np.zeros((stop - start, len(self.candidates)), dtype=bool)
        c = np.asarray(self.conflicts, dtype=np.int64).reshape(-1, 2)
        c = c[(c[:, 0] >= start) & (c[:, 0] < stop)]
        if len(c):
            np.logical_or.at(out, c[:, 0] - start, self.near[:, c[:, 1]].T)
        return out


def frame_figures(model, q: np.ndarray, warping: bool = True, backend: str = "warp",
                  contact: ContactProbe | None = None, chunk: int = CHUNK_FRAMES,
                  progress: ProgressCallback | None = None) -> FrameFigures:
    """Volume change, largest node displacement and (with ``contact``) penetration and contact
    area of every frame of ``q`` (F, m), reconstructing ``chunk`` frames at a time (float64)."""
    from tonguevis.sim.contact import contact_frames

    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    n_frames = len(q)
    volume = np.empty(n_frames)
    largest = np.empty(n_frames)
    pen = np.empty(n_frames) if contact is not None else None
    area = np.empty(n_frames) if contact is not None else None
    for start in range(0, n_frames, chunk):
        stop = min(start + chunk, n_frames)
        d = model.displacements(q[start:stop], warping=warping, backend=backend)
        volume[start:stop] = model.volume_change(d, backend=backend)
        largest[start:stop] = np.sqrt(np.einsum("fnc,fnc->fn", d, d).max(axis=1))
        if contact is not None:
            pen[start:stop], area[start:stop] = contact_frames(
                d, contact.points, contact.candidates, contact.palate, contact.jaw_offset[start:stop],
                contact.faces, contact.exclude(start, stop))
        report(progress, stop, n_frames, "volume and amplification, frame by frame")
    return FrameFigures(volume, largest, pen, area)
