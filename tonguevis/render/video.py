"""Exports of a simulated motion without Qt: the four views as an MP4 with the sound, and a VTK series.

The video renders the same four-view scene as the app off screen and hands the
pictures, with the WAV slice of the same time range, to :func:`tonguevis.render.mp4.write_mp4`,
so the MP4's picture and sound share one time base.  The VTK series is
:func:`tonguevis.sim.vtk_series.write_vtk_series` with the app's energy density added.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.errors import ExportError

__all__ = ["ExportError", "VIDEO_FPS", "VIDEO_SIZE", "export_video", "export_vtk_series", "frame_times"]

VIDEO_SIZE = (1280, 720)
VIDEO_FPS = 25


def frame_times(start: float, end: float, fps: float) -> np.ndarray:
    """Video frame times from ``start`` up to (not past) ``end``, seconds."""
    count = max(1, int(np.floor((end - start) * fps + 1e-9)))
    return start + np.arange(count) / fps


def export_video(session, out, start: float | None = None, end: float | None = None, fps: int = VIDEO_FPS,
                 size: tuple[int, int] = VIDEO_SIZE, mode: str = "displacement",
                 progress: ProgressCallback | None = None, frame: str = "head") -> Path:
    """Render ``session`` (simulated) from ``start`` to ``end`` seconds into an MP4 at ``out``.

    frame : "head" (default: the tongue and jaw carried by the jaw's motion, the palate
    fixed) or "jaw" (the jaw's motion removed); every picture says which.
    """
    import pyvista as pv

    from tonguevis.render.drawing import draw_frame
    from tonguevis.render.mp4 import write_mp4
    from tonguevis.render.scene import TongueScene, frame_text, scene_setup, surface_faces
    from tonguevis.sim.reference import check_reference

    check_reference(frame)
    frames = session.frames
    if frames is None:
        raise ExportError("nothing to export: the recording has not been simulated", session.path)
    out = Path(out)
    t0 = frames.times[0] if start is None else max(float(start), float(frames.times[0]))
    t1 = frames.times[-1] if end is None else min(float(end), float(frames.times[-1]))
    if not t1 > t0:
        raise ExportError(f"empty time range {t0:.3f}..{t1:.3f} s (the motion spans "
                          f"{frames.times[0]:.3f}..{frames.times[-1]:.3f} s)", out)
    width, height = (int(size[0]) // 2 * 2, int(size[1]) // 2 * 2)  # yuv420p needs even sizes
    plotter = pv.Plotter(shape="1|3", splitting_position=0.72, off_screen=True, window_size=(width, height))
    scene = TongueScene(plotter)
    motion = frames.motion
    scene.build(frames.points[0], surface_faces(motion.model), **scene_setup(session))
    scene.set_mode(mode)
    times = frame_times(t0, t1, fps)
    sound = None
    audio = session.recording.audio
    if audio is not None and len(audio.samples):
        from tonguevis.io.recording import Audio

        a = int(max(0, round((t0 - audio.offset) * audio.rate)))
        b = int(min(len(audio.samples), round((t0 - audio.offset + len(times) / fps) * audio.rate)))
        sound = Audio(np.asarray(audio.samples[a:b]), audio.rate)

    def pictures():
        for k, t in enumerate(times):
            i = frames.frame_at(t)
            drawn = draw_frame(session, i, frame, mode)
            scene.update(drawn.points, drawn.scalars, drawn.sensor_points, drawn.targets,
                         frame_text(frames, i, session.productions, drawn.caption), render=False,
                         context_offsets=drawn.context_offsets, context_shapes=drawn.context_shapes)
            scene.set_view_labels(f" · {drawn.caption.split(':')[0]}")
            yield plotter.screenshot(None, return_img=True, window_size=(width, height))
            report(progress, k + 1, len(times), "rendering video frames")

    try:
        return write_mp4(out, pictures(), (width, height), fps, audio=sound)
    finally:
        plotter.close()


def export_vtk_series(session, folder, progress: ProgressCallback | None = None, frame: str = "head") -> Path:
    """Write ``session``'s motion as ``frame_XXXXX.vtu`` files and ``motion.pvd`` into ``folder``; returns the .pvd.

    The series of :meth:`tonguevis.sim.motion.Motion.to_vtk_series` (point data displacement
    and deformation in m, displacement_mm; README.txt and jaw_offset.csv say which frame) with
    the elastic energy density the app colours by: ``energy_density`` in J/m³ per node, of the
    unwarped modal displacement (:class:`~tonguevis.render.frames.NodalEnergy`).

    frame : "head" (default: the tongue carried by the jaw's translation, the palate's frame)
    or "jaw" (as simulated).
    """
    from tonguevis.render.frames import NodalEnergy
    from tonguevis.sim.vtk_series import write_vtk_series

    if session.frames is None:
        raise ExportError("nothing to export: the recording has not been simulated", session.path)
    motion = session.frames.motion
    energy = NodalEnergy(motion.model, motion.q.shape[1], np.arange(motion.model.mesh.n_nodes))
    return write_vtk_series(motion, folder, frame=frame, progress=progress,
                            extra_fields=lambda idx: {"energy_density": energy(motion.q[idx])})
