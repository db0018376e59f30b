"""Generated recordings with the quirks of real EMA, cut from the demo /ta/ (data/spk1_ta.tsv).

Each helper returns a :class:`~tonguevis.io.Recording`; :func:`write` puts one
in a file (CSV, or an NDI Wave TSV whose missing samples get status 119 and
empty fields, as a real bad-status stretch does).  The demo has the sensors
TT, TD, TL, TR (+ JAW and three head references); it rests still until 4.9 s,
then says five /ta/ trains.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tonguevis.paths import DATA_DIR

DEMO = DATA_DIR / "spk1_ta.tsv"
SPEECH_S = (5.13, 9.12)  # the first two trains of the demo /ta/


def demo(start: float = 3.0, end: float = 10.0):
    """The demo /ta/ from ``start`` to ``end`` s, clock from 0, without sound, labels or orientations."""
    from tonguevis.workflows import open_recording

    if not DEMO.exists():
        pytest.skip(f"demo corpus not built: {DEMO}")
    rec = open_recording(DEMO, audio=False, labels=False)
    keep = (rec.times >= start - 1e-9) & (rec.times <= end + 1e-9)
    meta = {k: v for k, v in rec.metadata.items() if k in ("format", "original_unit", "frame")}
    return replace(rec, times=rec.times[keep] - rec.times[keep][0], audio=None, labels=[], orientations={},
                   sensors={n: v[keep].copy() for n, v in rec.sensors.items()}, metadata=meta)


def with_dropout(rec, sensor: str, start: float, seconds: float):
    """A copy with ``sensor`` missing (NaN) from ``start`` for ``seconds`` (to the end if that is past it)."""
    lost = (rec.times >= start - 1e-9) & (rec.times < start + seconds - 1e-9)
    x = rec.sensors[sensor].copy()
    x[lost] = np.nan
    return rec.with_sensors({**rec.sensors, sensor: x})


def without(rec, sensor: str):
    """A copy whose ``sensor`` has no valid sample at all (a coil that never worked)."""
    return rec.with_sensors({**rec.sensors, sensor: np.full_like(rec.sensors[sensor], np.nan)})


def _interpolated(rec, times: np.ndarray):
    """Every sensor at ``times`` (cubic, through the recording's own samples)."""
    from scipy.interpolate import CubicSpline

    return {n: CubicSpline(rec.times, v, axis=0)(times) for n, v in rec.sensors.items()}


def resampled(rec, rate: float):
    """The recording on a uniform clock of ``rate`` Hz (cubic interpolation of the samples)."""
    n = int(np.floor((rec.times[-1] - rec.times[0]) * rate + 1e-9)) + 1
    times = rec.times[0] + np.arange(n) / rate
    return replace(rec, rate=float(rate), times=times, sensors=_interpolated(rec, times))


def jittered(rec, jitter_s: float = 0.003, drop_every: int | None = None, seed: int = 0):
    """Irregular timestamps: each sample taken up to ``jitter_s`` off its nominal time (the positions are
    those at the jittered times), and every ``drop_every``-th frame lost (a time gap, as dropped frames give)."""
    rng = np.random.default_rng(seed)
    times = rec.times + rng.uniform(-jitter_s, jitter_s, size=rec.n_samples)
    times[0], times[-1] = rec.times[0], rec.times[-1]
    keep = np.ones(rec.n_samples, dtype=bool)
    if drop_every:
        keep[drop_every::drop_every] = False
        keep[-1] = True
    times = times[keep]
    return replace(rec, times=times, sensors=_interpolated(rec, times))


def write(rec, path: Path) -> Path:
    """``rec`` written to ``path`` (.csv, or .tsv: NDI Wave with the demo's Ids and a sensor_map.json beside)."""
    from tonguevis.io import write_recording

    path = Path(path)
    if path.suffix == ".tsv":
        ids = {name: k for k, name in enumerate(rec.sensor_names)}
        write_recording(rec, path, sensor_map=ids)
        (path.parent / "sensor_map.json").write_text(json.dumps({"sensors": ids}))
    else:
        write_recording(rec, path)
    return path
