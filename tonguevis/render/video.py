"""Exports of a simulated motion without Qt: MP4 with the sound, and VTK series.

The video renders the same four-view scene off screen, pipes raw RGB frames
into the ffmpeg binary that imageio-ffmpeg ships, and muxes the WAV slice of
the same time range, so the MP4's picture and sound share one time base.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.errors import TonguevisError

VIDEO_SIZE = (1280, 720)
VIDEO_FPS = 25


class ExportError(TonguevisError):
    """An export (video, VTK series) failed."""


def ffmpeg_exe() -> str:
    try:
        import imageio_ffmpeg
    except ImportError as exc:
        raise ExportError("video export needs imageio-ffmpeg (pip install imageio-ffmpeg)") from exc
    return imageio_ffmpeg.get_ffmpeg_exe()


def probe_streams(path) -> list[str]:
    """Stream kinds ('video', 'audio') of a media file, read from ``ffmpeg -i``."""
    out = subprocess.run([ffmpeg_exe(), "-hide_banner", "-i", str(path)], capture_output=True, text=True)
    kinds = []
    for line in out.stderr.splitlines():
        line = line.strip()
        if line.startswith("Stream #"):
            for kind in ("Video", "Audio"):
                if f": {kind}:" in line:
                    kinds.append(kind.lower())
    return kinds


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
    with tempfile.TemporaryDirectory(prefix="tonguevis-video-") as tmp:
        command = [ffmpeg_exe(), "-y", "-hide_banner", "-loglevel", "error",
                   "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{width}x{height}", "-r", str(fps), "-i", "-"]
        audio = session.recording.audio
        if audio is not None and len(audio.samples):
            from tonguevis.io.recording import Audio
            from tonguevis.io.wav import write_wav

            a = int(max(0, round((t0 - audio.offset) * audio.rate)))
            b = int(min(len(audio.samples), round((t0 - audio.offset + len(times) / fps) * audio.rate)))
            wav = Path(tmp) / "audio.wav"
            write_wav(Audio(np.asarray(audio.samples[a:b]), audio.rate), wav)
            command += ["-i", str(wav), "-c:a", "aac", "-b:a", "128k"]
        partial = Path(tmp) / "video.mp4"
        command += ["-c:v", "libx264", "-preset", "veryfast", "-crf", "20", "-pix_fmt", "yuv420p",
                    "-shortest", "-f", "mp4", str(partial)]
        process = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            for k, t in enumerate(times):
                i = frames.frame_at(t)
                drawn = draw_frame(session, i, frame, mode)
                scene.update(drawn.points, drawn.scalars, drawn.sensor_points, drawn.targets,
                             frame_text(frames, i, session.productions, drawn.caption), render=False,
                             context_offsets=drawn.context_offsets)
                scene.set_view_labels(f" · {drawn.caption.split(':')[0]}")
                image = plotter.screenshot(None, return_img=True, window_size=(width, height))
                process.stdin.write(np.ascontiguousarray(image[:, :, :3]).tobytes())
                report(progress, k + 1, len(times), "rendering video frames")
            process.stdin.close()
            error = process.stderr.read().decode(errors="replace")
            if process.wait() != 0:
                raise ExportError(f"ffmpeg failed: {error.strip()[-500:]}", out)
        except BaseException:
            process.kill()
            process.wait()
            raise
        finally:
            plotter.close()
        out.parent.mkdir(parents=True, exist_ok=True)
        os.replace(partial, out) if _same_device(partial, out) else _copy_replace(partial, out)
    return out


def _same_device(a: Path, b: Path) -> bool:
    try:
        return os.stat(a).st_dev == os.stat(b.parent).st_dev
    except OSError:
        return False


def _copy_replace(source: Path, target: Path) -> None:
    import shutil

    tmp = target.with_name(f".{target.name}.partial")
    shutil.copyfile(source, tmp)
    os.replace(tmp, target)


def export_vtk_series(session, folder, progress: ProgressCallback | None = None, frame: str = "head") -> Path:
    """Write every frame as ``frame_XXXXX.vtu`` (tets; point data displacement_m from rest in
    ``frame``, deformation_m the tongue's own (jaw frame), energy density in J/m³; field data
    reference_frame, a sentence, and jaw_offset_m) and ``motion.pvd`` (the series, with times
    in seconds) into ``folder``, with README.txt and jaw_offset.csv saying which frame.

    frame : "head" (default: the tongue carried by the jaw's translation, the palate's frame)
    or "jaw" (as simulated).
    """
    import pyvista as pv

    from tonguevis.sim.reference import describe, jaw_moves, tongue_offset, write_export_notes

    frames = session.frames
    if frames is None:
        raise ExportError("nothing to export: the recording has not been simulated", session.path)
    frames = frames.whole_mesh()  # every node: the view's frames compute the surface only
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    mesh = frames.motion.model.mesh
    cells = np.hstack([np.full((mesh.n_tets, 1), 4), mesh.tets]).ravel()
    grid = pv.UnstructuredGrid(cells, np.full(mesh.n_tets, pv.CellType.TETRA, dtype=np.uint8),
                               np.asarray(mesh.points, dtype=np.float64))
    offset = tongue_offset(frames.motion, frame)
    jaw = tongue_offset(frames.motion, "head")
    caption = describe(frame, jaw_moves(frames.motion))
    entries = []
    for i, t in enumerate(frames.times):
        grid.points = frames.points[i].astype(np.float64) + offset[i]
        grid.point_data["displacement_m"] = grid.points - mesh.points
        grid.point_data["deformation_m"] = frames.points[i] - mesh.points
        grid.point_data["energy_density_J_m3"] = frames.scalars["energy"][i]
        grid.field_data["reference_frame"] = [caption]
        grid.field_data["jaw_offset_m"] = jaw[i]
        name = f"frame_{i:05d}.vtu"
        tmp = folder / f".{name}.partial.vtu"
        grid.save(tmp)
        os.replace(tmp, folder / name)
        entries.append(f'    <DataSet timestep="{t:.6f}" part="0" file="{name}"/>')
        if i % 20 == 0:
            report(progress, i, frames.n_frames, "writing VTK frames")
    pvd = ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
           + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n")
    tmp = folder / ".motion.pvd.partial"
    tmp.write_text(pvd, encoding="utf-8")
    os.replace(tmp, folder / "motion.pvd")
    write_export_notes(folder, frames.motion, frame, suffix="_m")
    report(progress, frames.n_frames, frames.n_frames, "VTK series written")
    return folder / "motion.pvd"
