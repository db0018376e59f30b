"""The one MP4 writer of tonguevis: RGB frames (and optionally a sound) to H.264 through imageio-ffmpeg.

Every video tonguevis writes (the motion's four views with their sound, the morph's
play-through) goes through :func:`write_mp4`: frames are piped to the ffmpeg binary
that imageio-ffmpeg ships, encoded as H.264 in yuv420p (what every player reads), the
sound muxed as AAC, and the file is written under a temporary name and renamed when
complete (:func:`tonguevis._files.atomic_write`), so a failed or cancelled export
leaves nothing in place of the user's file.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Iterable

import numpy as np

from tonguevis._files import atomic_write
from tonguevis.errors import ExportError

#: H.264 constant rate factor (0 lossless .. 51 worst) and x264 preset of the motion's video.
CRF = 20
PRESET = "veryfast"
AUDIO_BITRATE = "128k"


def _imageio_ffmpeg():
    try:
        import imageio_ffmpeg
    except ImportError as exc:
        raise ExportError("video export needs imageio-ffmpeg (pip install imageio-ffmpeg)") from exc
    return imageio_ffmpeg


def ffmpeg_exe() -> str:
    """Path of the ffmpeg binary imageio-ffmpeg ships (ExportError without imageio-ffmpeg)."""
    return _imageio_ffmpeg().get_ffmpeg_exe()


def probe_streams(path) -> list[str]:
    """Stream kinds ('video', 'audio') of a media file, read from ``ffmpeg -i``."""
    import subprocess

    out = subprocess.run([ffmpeg_exe(), "-hide_banner", "-i", str(path)], capture_output=True, text=True)
    kinds = []
    for line in out.stderr.splitlines():
        line = line.strip()
        if line.startswith("Stream #"):
            for kind in ("Video", "Audio"):
                if f": {kind}:" in line:
                    kinds.append(kind.lower())
    return kinds


class _Abort(BaseException):
    """Thrown into imageio-ffmpeg's writer to make it kill ffmpeg (its policy for a BaseException)."""


def _kill(writer) -> None:
    """Stop ffmpeg at once: the file it would finish is deleted anyway."""
    try:
        writer.throw(_Abort())
    except (_Abort, StopIteration, OSError):
        pass


def write_mp4(path, images: Iterable[np.ndarray], size: tuple[int, int], fps: float, audio=None,
              crf: int = CRF, preset: str = PRESET) -> Path:
    """Encode ``images`` into an MP4 at ``path``; returns ``path``.

    images : iterable of (height, width, 3 or 4) uint8 RGB(A) pictures (the alpha is dropped),
        each ``size`` = (width, height) pixels; it is consumed as the video is written, so a
        generator renders one frame at a time.  Even sizes keep the picture unscaled (yuv420p
        halves the colour resolution; an odd side is padded to even by ffmpeg's scaler).
    fps : frames per second.
    audio : :class:`tonguevis.io.recording.Audio` (samples, rate) starting with the first
        frame, muxed as AAC; the file is cut to the shorter of picture and sound.
    crf, preset : H.264 quality (constant rate factor) and x264 speed preset.
    A picture of the wrong size or an ffmpeg failure is an :class:`ExportError` naming ``path``.
    """
    imageio_ffmpeg = _imageio_ffmpeg()
    path = Path(path)
    width, height = int(size[0]), int(size[1])
    path.parent.mkdir(parents=True, exist_ok=True)

    def write(tmp: Path) -> None:
        with tempfile.TemporaryDirectory(prefix="tonguevis-mp4-") as folder:
            output = ["-preset", str(preset), "-crf", str(int(crf))]
            sound = {}
            if audio is not None and len(audio.samples):
                from tonguevis.io.wav import write_wav

                wav = Path(folder) / "audio.wav"
                write_wav(audio, wav)
                sound = dict(audio_path=str(wav), audio_codec="aac")
                output += ["-b:a", AUDIO_BITRATE, "-shortest"]
            writer = imageio_ffmpeg.write_frames(str(tmp), (width, height), fps=fps, codec="libx264", quality=None,
                                                 macro_block_size=2, ffmpeg_log_level="error",
                                                 output_params=output + ["-f", "mp4"], **sound)
            writer.send(None)  # starts ffmpeg
            try:
                for image in images:
                    image = np.asarray(image)
                    if image.shape[:2] != (height, width):
                        raise ExportError(f"a picture of {image.shape[1]}x{image.shape[0]} pixels in a "
                                          f"{width}x{height} video", path)
                    try:
                        writer.send(np.ascontiguousarray(image[:, :, :3], dtype=np.uint8))
                    except OSError as exc:  # ffmpeg stopped (bad option, disk full); its message is in exc
                        raise ExportError(f"ffmpeg failed: {str(exc).strip()[-500:]}", path) from exc
            except BaseException:
                _kill(writer)
                raise
            writer.close()  # ffmpeg finishes the file
        # imageio-ffmpeg does not check ffmpeg's exit status: a file without a readable
        # video stream is a failure that would otherwise pass silently.
        if "video" not in probe_streams(tmp):
            raise ExportError("ffmpeg wrote no readable video", path)

    atomic_write(path, write)
    return path
