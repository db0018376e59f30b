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

On the compiled backend (what ``simulate`` runs) a chunk is its float32
products Φq and Wq and one compiled pass per frame that warps, measures and
drops it (:func:`tonguevis.sim.kernels.surface_figures`): 30 minutes cost 7 s
of one core instead of 14 (volume change within 1e-8 and the largest
displacement within 1e-8 m of the float64 reference).  With a palate, contact
is measured on the candidate nodes alone (the only ones that can touch it:
their float64 displacements, the clearances in one compiled pass), the same
penetration and contact area as from the whole surface.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from tonguevis._memory import release_freed_memory
from tonguevis._progress import ProgressCallback, report
from tonguevis.sim.model import CHUNK_FRAMES


@dataclass
class FrameFigures:
    """Per-frame figures of a motion (F frames).

    volume_change : (F,) (V - V_rest) / V_rest of the (warped) mesh.
    largest_displacement : (F,) metres, the largest displacement of a surface node (what the views
        draw; an inside node goes a few per cent further in about 1 % of the demo's frames).
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
                  progress: ProgressCallback | None = None, workers: int | None = None) -> FrameFigures:
    """Volume change, largest surface displacement and (with ``contact``) penetration and contact
    area of every frame of ``q`` (F, m), reconstructing ``chunk`` frames at a time (float64; on the
    "warp" backend the volume's and largest displacement's products in float32, see the module docstring).

    Only the surface nodes are reconstructed (41 % of the shipped tongue's): the volume is the
    flux through the surface, contact happens there, and the far field a clinician sees is there.

    The chunks are independent: ``workers`` threads (default: one per core, at most 4) take
    them in turn, each with one BLAS thread (the products release the GIL, and so do the
    compiled kernels, which run on one core each), so a long motion's pass uses every core;
    at most ``workers`` chunks are in memory at once.
    """
    from concurrent.futures import ThreadPoolExecutor

    from tonguevis._blas import single_threaded_blas

    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    n_frames = len(q)
    volume = np.empty(n_frames)
    largest = np.empty(n_frames)
    pen = np.empty(n_frames) if contact is not None else None
    area = np.empty(n_frames) if contact is not None else None
    starts = range(0, n_frames, chunk)
    if workers is None:
        workers = min(4, os.cpu_count() or 1)

    surface = model.surface_nodes
    surface_points = model.mesh.points[surface]
    surface_faces = np.searchsorted(surface, model.surface_faces)  # surface_nodes is sorted
    if contact is not None:  # the probe's node ids, renumbered within the surface
        local = np.full(len(contact.points), -1, dtype=np.int64)
        local[surface] = np.arange(len(surface))
        points, candidates, faces = contact.points[surface], local[contact.candidates], local[contact.faces]
        if (candidates < 0).any() or (faces < 0).any():
            raise ValueError("frame_figures: contact candidates and faces must lie on the surface")
        if backend == "warp":
            # Only candidates can touch the palate: their displacements (float64) are all contact needs,
            # the triangles of three candidates all the area can come from (renumbered among them).
            among = np.full(len(contact.points), -1, dtype=np.int64)
            among[contact.candidates] = np.arange(len(contact.candidates))
            cand_faces = among[contact.faces]
            cand_faces = cand_faces[np.all(cand_faces >= 0, axis=1)]
            cand_points = contact.points[contact.candidates]
    if contact is not None:
        from tonguevis.sim.contact import node_areas

        areas = node_areas(contact.points, contact.faces)  # every surface triangle's share, once

    def measure(start: int):
        from tonguevis.sim.contact import contact_frames

        stop = min(start + chunk, n_frames)
        if backend == "warp":  # warped, measured and dropped in one compiled pass
            from tonguevis.sim.kernels import surface_figures

            lin, w = model.modal_fields(q[start:stop], surface, warping, dtype=np.float32)
            volume, largest = surface_figures(lin, w, surface_points, surface_faces, warping)
            out = [volume / model.rest_volume - 1.0, largest]
            if contact is not None:
                d = model.displacements(q[start:stop], warping=warping, backend=backend, nodes=contact.candidates)
                out += contact_frames(d, cand_points, np.arange(len(cand_points)), contact.palate,
                                      contact.jaw_offset[start:stop], cand_faces, contact.exclude(start, stop),
                                      backend=backend, areas=areas[contact.candidates])
            return start, stop, out
        d = model.displacements(q[start:stop], warping=warping, backend=backend, nodes=surface)
        out = [model.volume_change(d, backend=backend, nodes=surface),
               np.sqrt(np.einsum("fnc,fnc->fn", d, d).max(axis=1))]
        if contact is not None:
            out += contact_frames(d, points, candidates, contact.palate, contact.jaw_offset[start:stop], faces,
                                  contact.exclude(start, stop), areas=areas[surface])
        return start, stop, out

    def store(result) -> None:
        start, stop, out = result
        volume[start:stop], largest[start:stop] = out[0], out[1]
        if contact is not None:
            pen[start:stop], area[start:stop] = out[2], out[3]
        report(progress, stop, n_frames, "volume and amplification, frame by frame")

    if workers <= 1 or len(starts) <= 1:
        for start in starts:
            store(measure(start))
    else:
        # The first chunk alone (it fills the model's caches: matrices, kernels), with one BLAS thread as
        # the others: the chunks round alike, and a threaded BLAS's wake-ups cost milliseconds a product
        # when the other core is busy (the demo with a palate: 5,200 -> 5,650 frames/s, best of 12).
        with single_threaded_blas():
            store(measure(starts[0]))
        with single_threaded_blas(), ThreadPoolExecutor(workers) as pool:
            for result in pool.map(measure, starts[1:]):
                store(result)
        release_freed_memory()
    return FrameFigures(volume, largest, pen, area)
