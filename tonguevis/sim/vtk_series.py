"""A motion as a VTK series for ParaView: one ``.vtu`` per frame and a ``.pvd`` collection.

The one VTK-series writer of tonguevis (:meth:`Motion.to_vtk_series`, ``tonguevis simulate
--vtk`` and the app's File ▸ Export VTK series all write through it).  Each
``frame_XXXXX.vtu`` holds the whole tetrahedral mesh at that frame, in metres, with point
data ``displacement`` (m, from rest in the chosen frame of reference), ``displacement_mm``
(its magnitude, mm) and ``deformation`` (m, the tongue's own, jaw frame), plus any extra
fields the caller adds (the app adds ``energy_density``, J/m³).  ``motion.pvd`` lists the
frames with their times (s); README.txt and jaw_offset.csv say which frame of reference
(:func:`tonguevis.sim.reference.write_export_notes`).  Every file is written under a
temporary name and renamed when complete.  A long recording is better exported as one
XDMF + HDF5 series (:mod:`tonguevis.sim.xdmf`): one ``.vtu`` per frame costs about 1 MB.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable
from xml.sax.saxutils import quoteattr

import numpy as np

from tonguevis._progress import ProgressCallback, report


def write_vtk_series(motion, folder, frames=None, frame: str = "head",
                     extra_fields: Callable[[np.ndarray], dict] | None = None,
                     progress: ProgressCallback | None = None, chunk: int | None = None) -> Path:
    """Write ``motion`` (frames ``frames``: a slice or index array, default all) into ``folder``; returns the .pvd.

    frame : "head" (default: the tongue carried by the jaw's translation, the palate's
        frame) or "jaw" (as simulated); see :mod:`tonguevis.sim.reference`.
    extra_fields : ``extra_fields(indices)`` -> {name: (c, n) or (c, n, 3) array}, more point
        data for the frames ``indices`` (c,) of a chunk, on every mesh node.
    chunk : frames reconstructed at once (default :data:`tonguevis.sim.model.CHUNK_FRAMES`).
    """
    import meshio

    from tonguevis._files import atomic_write, atomic_write_text
    from tonguevis.sim.reference import check_reference, tongue_offset, write_export_notes

    check_reference(frame)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    idx = np.atleast_1d(np.arange(motion.n_frames) if frames is None else np.arange(motion.n_frames)[frames])
    offset = tongue_offset(motion, frame)
    mesh = motion.model.mesh
    cells = [("tetra", np.asarray(mesh.tets))]
    entries = []
    done = 0
    for sel, deformations in motion.iter_displacements(chunk=chunk, frames=idx):
        extra = {} if extra_fields is None else extra_fields(sel)
        for k, i in enumerate(sel):
            deformation = deformations[k]
            disp = deformation + offset[i]
            point_data = {"displacement": disp, "displacement_mm": 1e3 * np.linalg.norm(disp, axis=1),
                          "deformation": deformation}
            point_data.update({name: np.asarray(values[k]) for name, values in extra.items()})
            grid = meshio.Mesh(mesh.points + disp, cells, point_data=point_data)
            name = f"frame_{int(i):05d}.vtu"
            atomic_write(folder / name, lambda tmp: meshio.write(tmp, grid, file_format="vtu"))
            entries.append(f'    <DataSet timestep="{motion.times[i]:.6f}" file={quoteattr(name)}/>')
        done += len(sel)
        report(progress, done, len(idx), "writing VTK frames")
    pvd = folder / "motion.pvd"
    atomic_write_text(pvd, '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                      + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n")
    write_export_notes(folder, motion, frame)
    return pvd
