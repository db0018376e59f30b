"""Finding the syllable trains of a recording (§3.2, first step).

With audio, a train is a stretch of sound: the short-time RMS envelope above
a threshold set between the noise floor and the speech level, with the short
silences inside a train (stop closures) bridged.  Without audio, a stretch in
which the tongue tip moves.
"""

from __future__ import annotations

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Recording
from tonguevis.preprocess._localpoly import savgol


def audio_envelope(samples: np.ndarray, rate: float, frame: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Short-time RMS level of audio.

    samples : (K,) float; rate : Hz; frame : seconds per (non-overlapping) frame.
    Returns (times (F,) seconds from the first sample to each frame's centre,
    level (F,) in dB relative to full scale, floored at -120 dB).
    """
    hop = max(1, int(round(frame * rate)))
    count = len(samples) // hop
    if count == 0:
        return np.zeros(0), np.zeros(0)
    blocks = np.asarray(samples[: count * hop], dtype=np.float64).reshape(count, hop)
    power = np.mean(np.where(np.isfinite(blocks), blocks, 0.0) ** 2, axis=1)
    level = 10.0 * np.log10(np.maximum(power, 1e-12))
    times = (np.arange(count) + 0.5) * hop / rate
    return times, level


def active_spans(times: np.ndarray, active: np.ndarray, step: float, max_gap: float,
                 min_duration: float) -> list[tuple[float, float]]:
    """Runs of True in ``active`` as (start, end) times, gaps < max_gap bridged.

    ``times`` are frame centres spaced ``step`` seconds; a span runs from the
    start of its first frame to the end of its last.  Spans shorter than
    ``min_duration`` are dropped.
    """
    padded = np.concatenate([[False], np.asarray(active, bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    starts, stops = edges[0::2], edges[1::2] - 1
    if starts.size == 0:
        return []
    begin = times[starts] - step / 2
    end = times[stops] + step / 2
    first = np.flatnonzero(np.concatenate([[True], begin[1:] - end[:-1] >= max_gap]))
    last = np.concatenate([first[1:] - 1, [len(begin) - 1]])
    return [(float(b), float(e)) for b, e in zip(begin[first], end[last]) if e - b >= min_duration]


def find_trains(rec: Recording, tip: str = "TT", max_gap: float = 0.35, min_duration: float = 0.4,
                use_audio: bool | None = None, threshold: float = 0.35) -> list[tuple[float, float]]:
    """The syllable trains of ``rec`` as (start_s, end_s) on the recording's clock.

    use_audio : None uses the audio when the recording has some.  From audio:
    10 ms RMS frames in dB; a frame is active above
    ``floor + threshold * (speech - floor)`` where floor and speech are the 5th
    and 99th percentiles of the level.  From kinematics: the tip's speed
    (Savitzky-Golay, 11 frames) above ``threshold`` times its 99th percentile.
    Silences shorter than ``max_gap`` seconds inside a train are bridged; spans
    shorter than ``min_duration`` seconds are dropped.
    """
    file = rec.metadata.get("file")
    if use_audio is None:
        use_audio = rec.audio is not None and len(rec.audio.samples) > 0
    if use_audio:
        if rec.audio is None:
            raise RecordingError("the recording has no audio to find trains in", file)
        times, level = audio_envelope(rec.audio.samples, rec.audio.rate)
        if times.size == 0:
            return []
        floor, speech = np.percentile(level, [5, 99])
        if speech - floor < 10.0:  # under 10 dB of contrast: no speech to find
            return []
        active = level > floor + threshold * (speech - floor)
        return [(b + rec.audio.offset, e + rec.audio.offset)
                for b, e in active_spans(times, active, times[1] - times[0] if times.size > 1 else 0.01,
                                         max_gap, min_duration)]
    if tip not in rec.sensors:
        raise RecordingError(f"no audio and no tip sensor {tip!r} to find trains from "
                             f"(sensors: {', '.join(rec.sensor_names)})", file)
    window = min(11, rec.n_samples - (1 - rec.n_samples % 2))
    if window < 5:
        return []
    speed = np.linalg.norm(savgol(rec.sensors[tip], window, 2, deriv=1, delta=1.0 / rec.rate), axis=1)
    finite = speed[np.isfinite(speed)]
    if finite.size == 0:
        return []
    active = speed > threshold * np.percentile(finite, 99)
    return active_spans(rec.times, active, 1.0 / rec.rate, max_gap, min_duration)
