"""The STI (Smith et al. 2000) and the time-normalised averages (issue 35), against the definition written out."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

from tonguevis.analysis.repetitions import PERCENT, repetitions


def direct_sti(times, z, rate, intervals) -> float:
    """The definition, step by step, in plain loops: 12 Hz low-pass (4th-order Butterworth, zero phase), each
    production's record linearly time-normalised (1001 points) and z-scored, the sample SD across productions
    at 0, 2, ..., 98 % (50 points), summed."""
    filtered = sosfiltfilt(butter(4, 12.0 / (rate / 2.0), output="sos"), z)
    records = []
    for start, end in intervals:
        record = np.interp(np.linspace(start, end, 1001), times, filtered)
        mean = sum(record) / len(record)
        sd = math.sqrt(sum((v - mean) ** 2 for v in record) / len(record))
        records.append([(v - mean) / sd for v in record])
    total = 0.0
    for k in range(0, 1000, 20):
        column = [r[k] for r in records]
        mean = sum(column) / len(column)
        total += math.sqrt(sum((v - mean) ** 2 for v in column) / (len(column) - 1))
    return total


def _smooth_signal(rate: float, seconds: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate)
    z = sum(rng.normal(scale=0.004) * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
            for f in rng.uniform(0.3, 9.0, size=12))
    return t, z + rng.normal(scale=2e-4, size=len(t))


def test_the_sti_is_the_definition():
    """On noisy random motion and irregular productions, every sensor's STI equals the definition in loops."""
    rate = 100.0
    t, z = _smooth_signal(rate, 30.0, 1)
    _, z2 = _smooth_signal(rate, 30.0, 2)
    rng = np.random.default_rng(5)
    starts = np.sort(rng.uniform(1.0, 27.0, size=9))
    intervals = [(s, s + rng.uniform(0.3, 1.2)) for s in starts]
    sensors = {"TT": np.column_stack([z2, z2, z]), "TD": np.column_stack([z, z, z2])}
    found = repetitions(t, rate, sensors, intervals)
    assert found.n == 9 and found.sensors == ["TT", "TD"]
    assert found.sti["TT"] == pytest.approx(direct_sti(t, z, rate, intervals), rel=1e-10)
    assert found.sti["TD"] == pytest.approx(direct_sti(t, z2, rate, intervals), rel=1e-10)
    assert found.subset([0, 3, 4]).sti["TT"] == pytest.approx(direct_sti(t, z, rate, [intervals[i] for i in (0, 3, 4)]),
                                                                rel=1e-10)
    assert math.isnan(found.subset([2]).sti["TT"])  # one production has no spread


def _productions(shapes, rate=1000.0, seed=0):
    """A recording of productions: production k is offset_k + amplitude_k * shape_k(u), u the normalised time over
    a duration of 1.0-1.5 s, joined by 1.5 s ramps between the offsets; the shapes and ramps are smooth to the
    second derivative where they meet, so the 12 Hz low-pass leaves them as they are; (times, z, intervals)."""
    rng = np.random.default_rng(seed)
    pieces, intervals, level = [np.zeros(int(rate))], [], 0.0
    now = 1.0
    ramp = np.arange(int(1.5 * rate)) / int(1.5 * rate)
    smoother = 6 * ramp ** 5 - 15 * ramp ** 4 + 10 * ramp ** 3
    for shape in shapes:
        duration, amplitude, offset = rng.uniform(1.0, 1.5), rng.uniform(3e-3, 9e-3), rng.uniform(-5e-3, 5e-3)
        pieces.append(level + (offset - level) * smoother)
        now += len(ramp) / rate
        n = int(round(duration * rate))  # the next piece's first sample is this one's end: shape(1) = 0
        pieces.append(offset + amplitude * shape(np.arange(n) / n))
        intervals.append((now, now + n / rate))
        now += n / rate
        level = offset
    pieces.append(np.full(int(rate), level))
    z = np.concatenate(pieces)
    return np.arange(len(z)) / rate, z, intervals


def _a(u):
    return np.sin(np.pi * np.asarray(u)) ** 4


def _b(u):
    u = np.asarray(u)
    return np.sin(np.pi * u) ** 4 * (1.0 + 0.9 * np.sin(2 * np.pi * u))


def _zscored_on_the_record(shape):
    u = np.linspace(0.0, 1.0, 1001)
    v = shape(u)
    return ((v - v.mean()) / v.std())[:1000:20]  # 0, 2, ..., 98 %


def test_known_variability():
    """Repetitions of one shape, whatever their duration, amplitude and offset: STI 0.  Half of one shape and half
    of another: at every point the SD is |A - B| / 2 * sqrt(2m / (2m - 1)), so the STI is known in closed form."""
    t, z, intervals = _productions([_a] * 8)
    same = repetitions(t, 1000.0, {"TT": np.column_stack([0 * z, 0 * z, z])}, intervals)
    assert same.sti["TT"] < 1e-3
    m = 6
    t, z, intervals = _productions([_a, _b] * m, seed=4)
    mixed = repetitions(t, 1000.0, {"TT": np.column_stack([0 * z, 0 * z, z])}, intervals)
    expected = float(np.sum(np.abs(_zscored_on_the_record(_a) - _zscored_on_the_record(_b)) / 2
                            * np.sqrt(2 * m / (2 * m - 1))))
    assert expected > 5.0
    assert mixed.sti["TT"] == pytest.approx(expected, rel=1e-4)


def test_the_averages_are_the_records_mean_and_sd():
    rate = 100.0
    t, z = _smooth_signal(rate, 20.0, 8)
    intervals = [(1.0 + 2 * k, 1.6 + 2 * k + 0.1 * k) for k in range(6)]
    found = repetitions(t, rate, {"TT": np.column_stack([z, z, z])}, intervals, labels=["ta"] * 6)
    rows = [r for r in found.average_rows() if r["sensor"] == "TT"]
    assert [r["time_percent"] for r in rows] == PERCENT.tolist() and all(r["n"] == 6 for r in rows)
    filtered = sosfiltfilt(butter(4, 12.0 / 50.0, output="sos"), z)
    at_half = [1e3 * np.interp(a + 0.5 * (b - a), t, filtered) for a, b in intervals]
    assert rows[50]["mean_z_mm"] == pytest.approx(np.mean(at_half), abs=1e-9)
    assert rows[50]["sd_z_mm"] == pytest.approx(np.std(at_half, ddof=1), abs=1e-9)
    document = found.as_json()
    assert document["n"] == 6 and document["points"] == 50 and set(document["sti"]) == {"TT"}
    assert document["productions"][2] == {"start_s": 5.0, "end_s": pytest.approx(5.8), "label": "ta"}
