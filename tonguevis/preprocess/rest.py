"""The rest pose: mean sensor positions over the longest still interval (§3.1).

The paper's speakers held the tongue at rest for about 5 s before speaking;
the mean positions over that interval are the reference configuration that
jaw correction, head correction and alignment refer to.
"""

from __future__ import annotations

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Recording
from tonguevis.preprocess._localpoly import savgol
from tonguevis.preprocess._names import is_reference, tongue_names


def _default_sensors(rec: Recording) -> list[str]:
    tongue = tongue_names(rec.sensor_names)
    return tongue or [n for n in rec.sensor_names if not is_reference(n)] or rec.sensor_names


def longest_run(mask: np.ndarray) -> tuple[int, int]:
    """(first, last) indices (inclusive) of the longest run of True, or (0, -1) if none."""
    padded = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    if edges.size == 0:
        return 0, -1
    starts, stops = edges[0::2], edges[1::2]
    best = int(np.argmax(stops - starts))
    return int(starts[best]), int(stops[best] - 1)


def find_rest_interval(rec: Recording, sensors=None, min_duration: float = 1.0,
                       max_speed: float = 0.01, window: int = 21) -> tuple[float, float]:
    """The longest interval in which the chosen sensors keep still.

    A sample is still when the speed of every chosen sensor (Savitzky-Golay
    derivative over ``window`` frames, order 2) stays below ``max_speed`` m/s
    (default 10 mm/s: speech moves the tongue at 50-200 mm/s, sensor noise of
    a few tenths of a millimetre gives a few mm/s after smoothing).  Invalid
    samples are never still.  Default sensors: the tongue sensors present,
    else every non-reference sensor.

    Returns (start_s, end_s): the times of the first and last still samples
    (both inclusive).  Raises RecordingError when no still interval lasts
    ``min_duration`` seconds.
    """
    names = _default_sensors(rec) if sensors is None else list(sensors)
    missing = [n for n in names if n not in rec.sensors]
    if missing or not names:
        raise RecordingError(
            f"rest detection needs sensors; missing {', '.join(missing) or 'all'} "
            f"(the recording has {', '.join(rec.sensor_names) or 'none'})", rec.metadata.get("file"))
    window = min(window, rec.n_samples - (1 - rec.n_samples % 2))
    if window < 5:
        raise RecordingError(f"recording too short for rest detection ({rec.n_samples} samples)",
                             rec.metadata.get("file"))
    stacked = np.stack([rec.sensors[n] for n in names], axis=1)  # (N, S, 3)
    velocity = savgol(stacked, window, 2, deriv=1, delta=1.0 / rec.rate)
    speed = np.linalg.norm(velocity, axis=2)  # NaN where invalid
    still = np.all(speed < max_speed, axis=1)  # NaN compares False
    first, last = longest_run(still)
    length = (last - first + 1) / rec.rate
    if last < first or length < min_duration:
        raise RecordingError(
            f"no still interval of {min_duration:g} s found in sensors {', '.join(names)} "
            f"(longest: {max(length, 0):.2f} s below {max_speed * 1000:g} mm/s); give the rest interval "
            "explicitly", rec.metadata.get("file"))
    return float(rec.times[first]), float(rec.times[last])


def rest_pose(rec: Recording, interval: tuple[float, float] | None = None,
              sensors=None) -> dict[str, np.ndarray]:
    """Mean position (3,) in metres of every sensor over the rest interval.

    interval : (start_s, end_s), both inclusive; detected with
    :func:`find_rest_interval` when None.  Invalid samples are ignored; a
    sensor with no valid sample in the interval raises RecordingError.
    """
    if interval is None:
        interval = find_rest_interval(rec)
    start, end = interval
    half_period = 0.5 / rec.rate
    inside = (rec.times >= start - half_period) & (rec.times <= end + half_period)
    if not np.any(inside):
        raise RecordingError(f"rest interval {start:g}-{end:g} s holds no sample", rec.metadata.get("file"))
    names = rec.sensor_names if sensors is None else list(sensors)
    pose = {}
    for name in names:
        part = rec.sensors[name][inside]
        ok = np.all(np.isfinite(part), axis=1)
        if not np.any(ok):
            raise RecordingError(f"sensor {name} has no valid sample in the rest interval "
                                 f"{start:g}-{end:g} s", rec.metadata.get("file"))
        pose[name] = part[ok].mean(axis=0)
    return pose
