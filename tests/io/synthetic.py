"""Small synthetic recordings for the reader tests (made here, never copied from real data)."""

from __future__ import annotations

import numpy as np

from tonguevis.io import Audio, Recording


def quaternions(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 4) random unit quaternions w, x, y, z with w >= 0."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1
    return q


def make_recording(
    n: int = 50,
    rate: float = 100.0,
    names=("TT", "TD", "TL", "TR", "JAW", "REF1"),
    audio_rate: float | None = 8000.0,
    seed: int = 0,
    with_gaps: bool = True,
    orientation: bool = True,
) -> Recording:
    """A recording of ``n`` frames of smooth motion in metres, some samples invalid (NaN)."""
    rng = np.random.default_rng(seed)
    times = 0.013 + np.arange(n) / rate
    sensors, orient = {}, {}
    for k, name in enumerate(names):
        base = rng.uniform(-0.05, 0.05, size=3)
        wobble = 0.004 * np.sin(2 * np.pi * (1.5 + k) * times)[:, None] * rng.normal(size=3)
        xyz = base + wobble
        if with_gaps and k == 1 and n > 10:
            xyz[3:6] = np.nan  # a sensor lost for three frames
        sensors[name] = xyz
        if orientation:
            q = quaternions(n, rng)
            q[~np.all(np.isfinite(xyz), axis=1)] = np.nan
            orient[name] = q
    audio = None
    if audio_rate:
        t = np.arange(int(times[-1] * audio_rate) + 10) / audio_rate
        audio = Audio(samples=0.5 * np.sin(2 * np.pi * 220.0 * t) * np.exp(-t), rate=audio_rate)
    return Recording(rate=rate, times=times, sensors=sensors, orientations=orient, audio=audio,
                     metadata={"orientation_kind": "quaternion_wxyz"} if orientation else {})
