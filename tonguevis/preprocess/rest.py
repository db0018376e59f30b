"""The rest pose: mean sensor positions over a rest interval (§3.1).

The paper's speakers held the tongue at rest for about 5 s before speaking;
the mean positions over that interval are the reference configuration that
jaw correction, head correction and alignment refer to.  Many real
recordings have no such still stretch (a read sentence, syllables from the
first frame), so :func:`choose_rest_interval` is the one place that decides
which interval every front end uses: the one the user gave, else the longest
still interval, else the stillest short window (with a warning), and says
which in a :class:`RestChoice`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Recording
from tonguevis.preprocess._localpoly import savgol
from tonguevis.preprocess._names import is_reference, tongue_names

from tonguevis._logging import warn_once

#: What a user can do when no rest is found: the command-line option and the app's menu item.
HOW_TO_GIVE_REST = "give one with --rest START END (seconds) or, in the app, Simulation ▸ Set rest interval…"
STILLEST_WINDOW_S = 0.2  # the fallback rest window when no still interval of MIN_REST_S exists
MIN_REST_S = 1.0
HOW = ("given", "detected", "stillest window")


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


def find_rest_interval(rec: Recording, sensors=None, min_duration: float = MIN_REST_S,
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
        raise RecordingError(f"recording too short for rest detection ({rec.n_samples} samples); "
                             f"{HOW_TO_GIVE_REST}", rec.metadata.get("file"))
    stacked = np.stack([rec.sensors[n] for n in names], axis=1)  # (N, S, 3)
    velocity = savgol(stacked, window, 2, deriv=1, delta=1.0 / rec.rate)
    speed = np.linalg.norm(velocity, axis=2)  # NaN where invalid
    still = np.all(speed < max_speed, axis=1)  # NaN compares False
    first, last = longest_run(still)
    length = (last - first + 1) / rec.rate
    if last < first or length < min_duration:
        raise RecordingError(
            f"no still interval of {min_duration:g} s found in sensors {', '.join(names)} "
            f"(longest: {max(length, 0):.2f} s below {max_speed * 1000:g} mm/s); {HOW_TO_GIVE_REST}",
            rec.metadata.get("file"))
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


def stillest_window(recording: Recording, sensors=None, duration: float = STILLEST_WINDOW_S) -> tuple[float, float]:
    """(start_s, end_s) of the window of ``duration`` where the sensors move least.

    Motion = the largest frame-to-frame step over the sensors; the window with
    the smallest mean motion wins (invalid samples count as moving).  Default
    sensors as :func:`find_rest_interval`.
    """
    names = _default_sensors(recording) if sensors is None else list(sensors)
    stacked = np.stack([recording.sensors[n] for n in names], axis=1)  # (N, S, 3)
    step = np.linalg.norm(np.diff(stacked, axis=0), axis=2).max(axis=1)
    width = max(1, int(round(duration * recording.rate)))
    if len(step) < width:
        raise RecordingError(f"recording too short ({recording.n_samples} samples, {recording.duration:.2f} s) "
                             f"to find a rest window of {duration:g} s in it; {HOW_TO_GIVE_REST}",
                             recording.metadata.get("file"))
    csum = np.concatenate([[0.0], np.cumsum(np.where(np.isfinite(step), step, 1e9))])
    means = (csum[width:] - csum[:-width]) / width
    start = int(np.argmin(means))
    return float(recording.times[start]), float(recording.times[start + width])


@dataclass(frozen=True)
class RestChoice:
    """The rest interval a simulation uses and how it was found.

    interval : (start_s, end_s), both inclusive, on the recording's clock.
    how : "given" (by the user), "detected" (the longest still interval) or
        "stillest window" (no still interval: the window where the sensors move least).
    reason : why the fallback was needed ("" unless how is "stillest window").
    """

    interval: tuple[float, float]
    how: str
    reason: str = ""

    def __post_init__(self) -> None:
        if self.how not in HOW:
            raise ValueError(f"how must be one of {', '.join(HOW)}, got {self.how!r}")
        object.__setattr__(self, "interval", (float(self.interval[0]), float(self.interval[1])))

    def describe(self) -> str:
        """One line for users, e.g. ``rest: 2.31-2.51 s (stillest window: no still second in the recording)``."""
        start, end = self.interval
        how = {"detected": "detected: the longest still stretch"}.get(self.how, self.how)
        return f"rest: {start:.2f}-{end:.2f} s ({how}{': ' + self.reason if self.reason else ''})"

    def as_dict(self) -> dict:
        """{"interval": [start_s, end_s], "how": ...} (plus "reason" when there is one), for JSON metadata."""
        out = {"interval": list(self.interval), "how": self.how}
        if self.reason:
            out["reason"] = self.reason
        return out

    @classmethod
    def from_dict(cls, data: dict) -> "RestChoice":
        """The inverse of :meth:`as_dict`."""
        return cls(tuple(data["interval"]), data["how"], data.get("reason", ""))


def choose_rest_interval(recording: Recording, sensors=None, given=None) -> RestChoice:
    """The rest interval to use for ``recording``, and how it was found.

    given : (start_s, end_s) from the user: checked (start before end, inside
        the recording, a valid sample of every sensor in it) and used as is;
        a bad one raises RecordingError naming the problem.
    Else the longest still interval of at least 1 s (:func:`find_rest_interval`);
    else the stillest 0.2 s window (:func:`stillest_window`), with a logged warning.
    Default sensors as :func:`find_rest_interval` (the tongue sensors present).
    """
    names = _default_sensors(recording) if sensors is None else list(sensors)
    if given is not None:
        return RestChoice(check_rest_interval(recording, given, names), "given")
    try:
        return RestChoice(find_rest_interval(recording, sensors=names), "detected")
    except RecordingError as exc:
        missing = [n for n in names if n not in recording.sensors]
        if missing or not names:
            raise
        detail = str(exc)
    interval = stillest_window(recording, names)
    short = recording.duration < MIN_REST_S
    reason = ("the recording is shorter than a second" if short
              else f"no still {'second' if MIN_REST_S == 1 else f'{MIN_REST_S:g} s'} in the recording")
    choice = RestChoice(interval, "stillest window", reason)
    say_stillest(recording, choice, detail)
    return choice


def say_stillest(recording: Recording, choice: RestChoice, detail: str = "") -> None:
    """The warning (once, one line; ``detail``, the longer why, at the info level) that the stillest window
    ``choice`` stands in for a rest the recording does not have."""
    start, end = choice.interval
    name = Path(str(recording.metadata.get("file") or "recording")).name
    warn_once(f"{name}: {choice.reason}; rest: the stillest {end - start:.1f} s, {start:.2f}-{end:.2f} s "
              "(--rest START END gives one)",
              f"{detail + '; ' if detail else ''}the stillest window {start:.2f}-{end:.2f} s stands in for the rest pose")


def rest_candidates(recording: Recording, sensors=None, count: int = 6) -> list[RestChoice]:
    """The rests :func:`choose_rest_interval` would take, best first, then the next stillest windows: the
    longest still interval of at least 1 s when there is one, then up to ``count`` stillest windows of
    :data:`STILLEST_WINDOW_S`, none overlapping another (for a caller that must reject some: a palate that
    cuts through the tongue there, :func:`tonguevis.sim.simulate.simulate`)."""
    names = _default_sensors(recording) if sensors is None else list(sensors)
    out: list[RestChoice] = []
    try:
        out.append(RestChoice(find_rest_interval(recording, sensors=names), "detected"))
    except RecordingError:
        pass
    stacked = np.stack([recording.sensors[n] for n in names], axis=1)  # (N, S, 3)
    step = np.linalg.norm(np.diff(stacked, axis=0), axis=2).max(axis=1)
    width = max(1, int(round(STILLEST_WINDOW_S * recording.rate)))
    if len(step) < width:
        return out
    csum = np.concatenate([[0.0], np.cumsum(np.where(np.isfinite(step), step, 1e9))])
    means = (csum[width:] - csum[:-width]) / width
    taken = [choice.interval for choice in out]
    reason = "the next stillest window" if out else "no still second in the recording"
    windows = 0
    for start in np.argsort(means, kind="stable"):
        if windows >= count or means[start] >= 1e8:  # 1e9 marks a missing sample: not still
            break
        t0, t1 = float(recording.times[start]), float(recording.times[start + width])
        if any(t0 < b + STILLEST_WINDOW_S and t1 > a - STILLEST_WINDOW_S for a, b in taken):  # apart from each
            continue
        taken.append((t0, t1))
        out.append(RestChoice((t0, t1), "stillest window", reason))
        windows += 1
    return out


def check_rest_interval(recording: Recording, interval, sensors=None) -> tuple[float, float]:
    """``interval`` as (start_s, end_s) floats if it can serve as a rest interval, else RecordingError.

    It must be two finite numbers, start before end, lie inside the recording
    (to half a sample period) and hold a valid sample of every one of ``sensors``.
    """
    file = recording.metadata.get("file")
    try:
        start, end = (float(v) for v in interval)
    except (TypeError, ValueError):
        raise RecordingError(f"a rest interval is two numbers START END in seconds, got {interval!r}", file) from None
    if not (np.isfinite(start) and np.isfinite(end)):
        raise RecordingError(f"rest interval {start:g}-{end:g} s: start and end must be finite seconds", file)
    if not start < end:
        raise RecordingError(f"rest interval {start:g}-{end:g} s: the end must come after the start", file)
    t0, t1 = float(recording.times[0]), float(recording.times[-1])
    half_period = 0.5 / recording.rate
    if start < t0 - half_period or end > t1 + half_period:
        raise RecordingError(f"rest interval {start:g}-{end:g} s is not inside the recording "
                             f"({t0:.2f}-{t1:.2f} s)", file)
    names = _default_sensors(recording) if sensors is None else list(sensors)
    inside = (recording.times >= start - half_period) & (recording.times <= end + half_period)
    if not np.any(inside):
        raise RecordingError(f"rest interval {start:g}-{end:g} s holds no sample", file)
    empty = [n for n in names if n in recording.sensors and not np.any(recording.valid(n)[inside])]
    if empty:
        raise RecordingError(f"rest interval {start:g}-{end:g} s holds no valid sample of "
                             f"{', '.join(empty)}", file)
    return start, end
