"""EMA for Praat: the sound and every sensor's x, y, z as channels of one WAV, with a sidecar naming them.

As ema2wav does (Buech et al., Interspeech 2022): Praat opens a multichannel WAV and shows every channel beside the
spectrogram, so the kinematics line up with the acoustics and the TextGrids of ``tonguevis syllables
--textgrid``.  :func:`write_ema_wav` writes

* ``OUT.wav``: IEEE float32 at the sound's rate (:data:`RATE_WITHOUT_SOUND` without one); channel 1 the
  sound (nominally in [-1, 1]) when there is one, then ``SENSOR_x``, ``SENSOR_y``, ``SENSOR_z`` of every
  sensor in millimetres (1.0 = 1 mm), head-corrected like the rest of tonguevis (x anterior, y left, z up),
  linearly interpolated from the EMA samples onto the sound's clock, gaps filled linearly (ends held);
* ``OUT.json``: each channel's name, unit and scale, the rate, the recording-clock time of the first
  sample, the frame, and the gaps that were filled, per sensor.

Sample 0 is the sound's first sample (its time on the recording's clock in ``start_s``), or the
recording's time 0 without sound: the TextGrids tonguevis writes start there too.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

#: Hz: the WAV's rate when the recording has no sound.
RATE_WITHOUT_SOUND = 16000
AXES = "xyz"


def _gaps(times: np.ndarray, valid: np.ndarray) -> list[list[float]]:
    """[start_s, end_s] of each run of invalid samples."""
    padded = np.concatenate([[False], ~valid, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return [[float(times[a]), float(times[b - 1])] for a, b in zip(edges[0::2], edges[1::2])]


def ema_channels(recording, head_correction: bool = True) -> tuple[np.ndarray, dict]:
    """((n, c) float32 samples, the sidecar dict) of ``recording``: see the module docstring."""
    from tonguevis.errors import RecordingError
    from tonguevis.preprocess.correction import head_corrected, head_references
    from tonguevis.preprocess.gestures import fill_gaps

    file = recording.metadata.get("file")
    if recording.n_samples < 2:
        raise RecordingError(f"the recording has {recording.n_samples} sample(s): nothing to export", file)
    corrected = head_corrected(recording) if head_correction else recording
    times = corrected.times
    audio = recording.audio if recording.audio is not None and len(recording.audio.samples) else None
    if audio is not None:
        rate, start = float(audio.rate), float(audio.offset)
        count = max(len(audio.samples), int(np.floor((times[-1] - start) * rate)) + 1)
    else:
        rate, start = float(RATE_WITHOUT_SOUND), min(0.0, float(times[0]))
        count = int(np.floor((times[-1] - start) * rate)) + 1
    clock = start + np.arange(count) / rate
    names = [n for n in corrected.sensor_names if np.isfinite(corrected.sensors[n]).any()]
    skipped = [n for n in corrected.sensor_names if n not in names]
    channels = [{"name": "sound", "unit": "", "scale": 1.0, "what": "the recording's sound"}] if audio is not None else []
    data = np.empty((count, len(channels) + 3 * len(names)), dtype=np.float32)
    if audio is not None:
        data[:, 0] = 0.0
        data[:len(audio.samples), 0] = audio.samples[:count]
    gaps, first = {}, len(channels)
    for k, name in enumerate(names):
        xyz = np.asarray(corrected.sensors[name], dtype=np.float64)
        valid = np.isfinite(xyz).all(axis=1)
        if not valid.all():
            gaps[name] = _gaps(times, valid)
        filled = fill_gaps(xyz)
        for axis in range(3):
            column = first + 3 * k + axis
            data[:, column] = (1e3 * np.interp(clock, times, filled[:, axis])).astype(np.float32)
        channels += [{"name": f"{name}_{a}", "unit": "mm", "scale": 1.0, "sensor": name, "axis": a} for a in AXES]
    references = head_references(recording) if head_correction else []
    sidecar = {
        "file": str(file) if file else None,
        "rate_hz": rate, "samples": count, "start_s": start,
        "channels": channels,
        "scale": "each EMA channel holds millimetres (1.0 = 1 mm); the sound its samples (nominally -1..1)",
        "frame": ("head-corrected by " + ", ".join(references) if references else "as recorded (no head references)")
                 + ": x anterior, y left, z up",
        "ema_rate_hz": float(recording.rate),
        "interpolation": "linear from the EMA samples onto the WAV's clock; held before the first and after the last",
        "gaps_filled": gaps,
        "left_out": skipped,
    }
    return data, sidecar


def sidecar_path(wav_path: str | os.PathLike) -> Path:
    """``OUT.wav`` -> ``OUT.json``."""
    return Path(wav_path).with_suffix(".json")


def write_ema_wav(recording, path: str | os.PathLike, head_correction: bool = True) -> tuple[Path, Path]:
    """Write ``path`` (the WAV) and its sidecar ``path`` with ``.json``; returns both paths."""
    from tonguevis._files import atomic_write_text
    from tonguevis.errors import TonguevisError
    from tonguevis.io.wav import write_wav_channels

    path = Path(path)
    if path.suffix.lower() != ".wav":
        raise TonguevisError(f"the EMA export is a WAV: name it OUT.wav, not {path.name}", path)
    data, sidecar = ema_channels(recording, head_correction)
    write_wav_channels(data, sidecar["rate_hz"], path)
    side = sidecar_path(path)
    atomic_write_text(side, json.dumps({**sidecar, "wav": path.name}, indent=1) + "\n")
    return path, side
