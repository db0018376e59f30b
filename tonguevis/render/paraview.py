"""The app's ParaView export: the motion as one XDMF + HDF5 time series, with the energy density (no Qt).

What :func:`tonguevis.sim.xdmf.write_xdmf` writes (the mesh once, every
exported frame's displacement in metres), plus the elastic energy density
(J/m³) per node that the app colours by, made from q chunk by chunk
(:class:`~tonguevis.render.frames.NodalEnergy`): memory does not grow with the
recording, and a 30-minute recording is a few GB instead of the 38 GB of one
``.vtu`` per frame (:func:`tonguevis.render.video.export_vtk_series`, still there).
"""

from __future__ import annotations

from pathlib import Path

from tonguevis._progress import ProgressCallback


def export_paraview(session, path, frame: str = "head", surface_only: bool = False, stride: int = 1,
                    progress: ProgressCallback | None = None) -> Path:
    """Write ``session``'s motion to ``path`` (.xdmf, and .h5 beside it); returns the .xdmf path.

    frame : "head" or "jaw" (see :mod:`tonguevis.sim.xdmf`); surface_only : the surface
    triangles only; stride : every ``stride``-th frame.  Point data: ``displacement`` (m)
    and ``energy_density`` (J/m³, of the unwarped modal displacement, as the app shows it).
    """
    from tonguevis.render.frames import NodalEnergy
    from tonguevis.errors import ExportError
    from tonguevis.sim.xdmf import export_nodes, write_xdmf

    motion = getattr(session, "motion", None)
    if motion is None:
        raise ExportError("nothing to export: the recording has not been simulated", getattr(session, "path", None))
    nodes, _, _ = export_nodes(motion.model, surface_only)
    energy = NodalEnergy(motion.model, motion.q.shape[1], nodes)
    return write_xdmf(motion, path, surface_only=surface_only, stride=stride, frame=frame,
                      extra_fields=lambda idx: {"energy_density": energy(motion.q[idx])}, progress=progress)
