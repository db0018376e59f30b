"""Consonant gestures in one articulator's motion: closures, releases, vowel targets, landmarks.

A CV syllable moves its consonant's articulator up to a closure and then down to the
vowel.  On real sessions that is embedded in other motion: isolated repetitions start
from a rest posture (tongue and jaw high), open a little (a short dip), rise fast to
the closure, fall to the vowel and return to rest; trains (the paper's ta-ta-ta...) go
from one vowel straight into the next closure.  The rules here work on both:

* the constriction signal is the articulator's vertical position (tongue sensors) or
  the negative lip aperture (lips), low-passed at 12 Hz (zero-phase, 4th-order
  Butterworth), so "up" always means "closing";
* a closure is a local maximum that rose by at least ``MIN_SIZE`` of the signal's range
  (1st-99th percentile; and at least ``MIN_SIZE_M``) within ``RISE_REACH`` before it (a consonant's closing movement
  takes 100-250 ms; a slow return to rest does not qualify) and falls by as much within
  ``FALL_REACH`` after it;
* of two candidates separated by a trough shallower than the troughs on both outer sides
  (by ``DIP`` of the range), the first is the rest posture before an opening dip, not a
  closure: a closure is followed by the vowel, the most open point around it;
* the release is the first moment after the closure maximum at which the articulator has
  come down 20 % of the way to the vowel target (the lowest point before the next rise).

Landmarks follow MVIEW's ``lp_findgest`` convention on the articulator's tangential
velocity with 20 % thresholds: gesture onset (GONS), peak velocity (PVEL), nucleus onset
(NONS), maximum constriction (MAXC, the lowest speed within 50 ms of the highest
position), nucleus offset (NOFFS), second peak velocity (PVEL2), gesture offset (GOFFS),
and the vowel target.  Where the speed never falls to 20 % of its peak (the /k/ dorsum
moves in a loop), the landmark is the lowest speed of its stretch and is listed in
``GestureLandmarks.fallbacks``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import butter, find_peaks, sosfiltfilt

#: Low-pass cut-off (Hz) of the constriction signal and of the landmarks' velocity.
CUTOFF_HZ = 12.0
#: A closure rises and falls by at least this fraction of the signal's 1st-99th percentile range.
MIN_SIZE = 0.25
#: Candidates between this fraction and MIN_SIZE are "near misses": reported, never kept.
NEAR_SIZE = 0.15
#: ... and never less than these (m): EMA sensor noise is a few tenths of a millimetre, a CV
#: closing movement several millimetres.
MIN_SIZE_M = 0.0015
NEAR_SIZE_M = 0.001
#: How far before a maximum the closing rise is looked for (s), and the fall after it (s).
RISE_REACH = 0.25
FALL_REACH = 0.40
#: A trough this much (fraction of range) shallower than both neighbouring troughs is an opening dip.
DIP = 0.15
#: Threshold of the landmarks (fraction of the peak velocity) and of the release (fraction of the fall).
VELOCITY_THRESHOLD = 0.20
RELEASE_FRACTION = 0.20
#: The closure (MAXC) is the lowest speed this close (s) to the highest position.
MAXC_REACH = 0.05
#: Longest search (s) for the vowel target after a closure when no later closure bounds it.
VOWEL_REACH = 0.8
#: The vowel ends where the articulator has come back this fraction of the way to the next maximum.
VOWEL_END_FRACTION = 0.80

LANDMARKS = ("gons", "pvel", "nons", "maxc", "noffs", "pvel2", "goffs", "vowel")
LANDMARK_NAMES = {"gons": "gesture onset", "pvel": "peak velocity", "nons": "nucleus onset",
                  "maxc": "maximum constriction", "noffs": "nucleus offset", "pvel2": "second peak velocity",
                  "goffs": "gesture offset", "vowel": "vowel target"}


def fill_gaps(values: np.ndarray) -> np.ndarray:
    """(N,) or (N, k) float with NaN samples linearly interpolated (ends held); all-NaN stays NaN."""
    values = np.array(values, dtype=np.float64)
    flat = values.reshape(len(values), -1)
    index = np.arange(len(values))
    for column in flat.T:
        ok = np.isfinite(column)
        if ok.any() and not ok.all():
            column[~ok] = np.interp(index[~ok], index[ok], column[ok])
    return values


def lowpass(values: np.ndarray, rate: float, cutoff: float = CUTOFF_HZ) -> np.ndarray:
    """Zero-phase 4th-order Butterworth low-pass along axis 0 (gaps filled first).

    values : (N,) or (N, k); rate : Hz.  Recordings too short for the filter's padding,
    or sampled too slowly for the cut-off, are returned gap-filled but unfiltered.
    """
    values = fill_gaps(values)
    cutoff = min(cutoff, 0.45 * rate)
    sos = butter(4, cutoff / (rate / 2.0), output="sos")
    if len(values) <= 3 * (2 * len(sos) + 1) or not np.isfinite(values).all():
        return values
    return sosfiltfilt(sos, values, axis=0)


@dataclass(frozen=True)
class Closure:
    """One consonant closure found in a constriction signal (sample indices, signal units).

    peak : the highest sample; size : min(rise, fall) around it; rise, fall : how far the
    signal rose within RISE_REACH before and fell within FALL_REACH after.
    """

    peak: int
    size: float
    rise: float
    fall: float


def _drop(signal: np.ndarray, peak: int, reach: int, step: int) -> float:
    """How far ``signal`` falls below its value at ``peak`` within ``reach`` samples in
    direction ``step`` (-1 before, +1 after), stopping at the first higher sample."""
    if step < 0:
        segment = signal[max(peak - reach, 0):peak][::-1]
    else:
        segment = signal[peak + 1:peak + 1 + reach]
    higher = np.flatnonzero(segment > signal[peak])
    if higher.size:
        segment = segment[:higher[0]]
    return float(signal[peak] - segment.min()) if segment.size else 0.0


def signal_range(signal: np.ndarray) -> float:
    """The 1st-99th percentile range of a constriction signal (robust to spikes)."""
    finite = signal[np.isfinite(signal)]
    if finite.size == 0:
        return 0.0
    low, high = np.percentile(finite, [1, 99])
    return float(high - low)


def closure_candidates(signal: np.ndarray, rate: float, scale: float | None = None,
                       min_size: float = NEAR_SIZE, floor: float = NEAR_SIZE_M) -> list[Closure]:
    """Every local maximum of ``signal`` (N,) whose rise and fall are at least ``min_size``
    of ``scale`` (default: :func:`signal_range`) and ``floor`` metres, in time order."""
    scale = signal_range(signal) if scale is None else scale
    if scale <= 0 or len(signal) < 3:
        return []
    threshold = max(min_size * scale, floor)
    rise_reach, fall_reach = int(round(RISE_REACH * rate)), int(round(FALL_REACH * rate))
    found = []
    for peak in find_peaks(signal)[0]:
        rise, fall = _drop(signal, peak, rise_reach, -1), _drop(signal, peak, fall_reach, +1)
        if min(rise, fall) >= threshold:
            found.append(Closure(int(peak), min(rise, fall), rise, fall))
    return found


def drop_rest_peaks(signal: np.ndarray, closures: list[Closure], scale: float, rate: float) -> list[Closure]:
    """Remove the rest postures that precede an opening dip (see the module docstring).

    A candidate is dropped when the trough after it is shallower, by ``DIP`` of ``scale``,
    than both the trough before it and the trough after the next candidate.  Repeated
    until nothing changes (each pass drops the earliest such candidate).
    """
    kept = list(closures)
    edge = int(round(FALL_REACH * rate))
    while len(kept) > 1:
        peaks = [c.peak for c in kept]
        after = [float(signal[a:b + 1].min()) for a, b in zip(peaks[:-1], peaks[1:])]
        after.append(float(signal[peaks[-1]:peaks[-1] + edge + 1].min()))
        before = [float(signal[max(peaks[0] - edge, 0):peaks[0] + 1].min())] + after[:-1]
        for i in range(len(kept) - 1):
            if after[i] - before[i] > DIP * scale and after[i] - after[i + 1] > DIP * scale:
                del kept[i]
                break
        else:
            break
    return kept


def find_closures(signal: np.ndarray, rate: float, scale: float | None = None) -> tuple[list[Closure], list[Closure]]:
    """The consonant closures of a (low-passed) constriction signal and the near misses.

    Returns (closures, near): closures at least ``MIN_SIZE`` of the range with the rest
    postures dropped; near misses are maxima between ``NEAR_SIZE`` and ``MIN_SIZE``.
    """
    scale = signal_range(signal) if scale is None else scale
    candidates = closure_candidates(signal, rate, scale, NEAR_SIZE, NEAR_SIZE_M)
    strong = [c for c in candidates if c.size >= max(MIN_SIZE * scale, MIN_SIZE_M)]
    near = [c for c in candidates if c.size < max(MIN_SIZE * scale, MIN_SIZE_M)]
    return drop_rest_peaks(signal, strong, scale, rate), near


def crossing_time(times: np.ndarray, signal: np.ndarray, start: int, level: float, step: int,
                  limit: int) -> float | None:
    """The first time, walking from sample ``start`` in direction ``step`` up to sample
    ``limit``, at which ``signal`` reaches ``level`` from above (linear interpolation
    between samples); None when it never does."""
    index = np.arange(start, limit + step, step)
    index = index[(index >= 0) & (index < len(signal))]
    if index.size < 2:
        return None
    below = np.flatnonzero(signal[index] <= level)
    if below.size == 0:
        return None
    k = int(below[0])
    if k == 0:
        return float(times[index[0]])
    a, b = index[k - 1], index[k]
    fraction = (signal[a] - level) / (signal[a] - signal[b]) if signal[a] != signal[b] else 1.0
    return float(times[a] + fraction * (times[b] - times[a]))


@dataclass
class GestureLandmarks:
    """The landmarks of one CV gesture on one articulator.

    times : landmark name (:data:`LANDMARKS`) -> time in s (NaN when not found);
    positions : name -> (3,) articulator position in metres (for the lips: the lower lip);
    peak_velocity, peak_velocity2 : tangential speed at PVEL and PVEL2 (m/s);
    fallbacks : landmarks placed at a speed minimum because the 20 % threshold was never crossed.
    """

    times: dict[str, float]
    positions: dict[str, np.ndarray]
    peak_velocity: float
    peak_velocity2: float
    fallbacks: list[str] = field(default_factory=list)

    def durations(self) -> dict[str, float]:
        """Gesture (GONS-GOFFS), nucleus (NONS-NOFFS), closing (GONS-NONS) and opening
        (NOFFS-GOFFS) durations in s."""
        t = self.times
        return {"gesture": t["goffs"] - t["gons"], "nucleus": t["noffs"] - t["nons"],
                "closing": t["nons"] - t["gons"], "opening": t["goffs"] - t["noffs"]}


def _threshold_index(speed: np.ndarray, start: int, stop: int, level: float, step: int) -> int | None:
    """First sample from ``start`` towards ``stop`` (inclusive) where speed <= level, else None."""
    index = np.arange(start, stop + step, step)
    index = index[(index >= 0) & (index < len(speed))]
    hit = np.flatnonzero(speed[index] <= level)
    return int(index[hit[0]]) if hit.size else None


def gesture_landmarks(times: np.ndarray, positions: np.ndarray, speed: np.ndarray, signal: np.ndarray,
                      peak: int, search_start: int, vowel: int, search_stop: int) -> GestureLandmarks:
    """``lp_findgest``'s landmarks of the gesture whose highest sample is ``peak``.

    times (N,) s; positions (N, 3) m (low-passed); speed (N,) m/s tangential speed;
    signal (N,) the constriction signal; search_start : first sample of the closing
    movement's search (the trough before); vowel : the vowel target's sample;
    search_stop : last sample of the opening movement's search.
    """
    fallbacks: list[str] = []
    reach = max(1, int(round(MAXC_REACH * (len(times) - 1) / max(times[-1] - times[0], 1e-9))))
    lo, hi = max(peak - reach, search_start), min(peak + reach, vowel)
    maxc = lo + int(np.argmin(speed[lo:hi + 1]))
    # closing movement: search_start .. maxc
    pvel = search_start + int(np.argmax(speed[search_start:maxc + 1])) if maxc > search_start else maxc
    level = VELOCITY_THRESHOLD * speed[pvel]
    gons = _threshold_index(speed, pvel, search_start, level, -1)
    if gons is None:
        gons = search_start + int(np.argmin(speed[search_start:pvel + 1]))
        fallbacks.append("gons")
    nons = _threshold_index(speed, pvel, maxc, level, +1)
    if nons is None:
        nons = maxc
        fallbacks.append("nons")
    # opening movement: maxc .. search_stop
    pvel2 = maxc + int(np.argmax(speed[maxc:max(vowel, maxc) + 1]))
    level2 = VELOCITY_THRESHOLD * speed[pvel2]
    noffs = _threshold_index(speed, pvel2, maxc, level2, -1)
    if noffs is None:
        noffs = maxc
        fallbacks.append("noffs")
    goffs = _threshold_index(speed, pvel2, search_stop, level2, +1)
    if goffs is None:
        goffs = pvel2 + int(np.argmin(speed[pvel2:search_stop + 1]))
        fallbacks.append("goffs")
    index = {"gons": gons, "pvel": pvel, "nons": nons, "maxc": maxc, "noffs": noffs, "pvel2": pvel2,
             "goffs": goffs, "vowel": vowel}
    return GestureLandmarks(times={k: float(times[i]) for k, i in index.items()},
                            positions={k: positions[i].copy() for k, i in index.items()},
                            peak_velocity=float(speed[pvel]), peak_velocity2=float(speed[pvel2]),
                            fallbacks=fallbacks)


def missing_landmarks() -> GestureLandmarks:
    """Landmarks of a production whose articulator has no valid samples (every time NaN)."""
    nan3 = np.full(3, np.nan)
    return GestureLandmarks({k: float("nan") for k in LANDMARKS}, {k: nan3.copy() for k in LANDMARKS},
                            float("nan"), float("nan"), list(LANDMARKS))
