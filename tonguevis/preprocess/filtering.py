"""Smoothing and time derivatives of sensor trajectories.

Seed 001 §4 smooths EMA with a third-order Savitzky-Golay filter over 21
frames; :func:`smooth` does that while respecting invalid (NaN) samples.
"""

from __future__ import annotations

import numpy as np

from tonguevis.errors import TonguevisError
from tonguevis.io.recording import Recording
from tonguevis.preprocess._localpoly import savgol


def _selected(rec: Recording, sensors) -> list[str]:
    names = rec.sensor_names if sensors is None else list(sensors)
    missing = [n for n in names if n not in rec.sensors]
    if missing:
        raise TonguevisError(
            f"no sensor(s) {', '.join(missing)} in the recording (it has {', '.join(rec.sensor_names)})",
            rec.metadata.get("file"),
        )
    return names


def smooth(rec: Recording, window: int = 21, order: int = 3, sensors=None) -> Recording:
    """A copy of ``rec`` with positions Savitzky-Golay smoothed (NaN-aware).

    window : odd number of frames (21 = 0.21 s at 100 Hz); order : polynomial
    degree.  Invalid samples stay NaN and do not contaminate their neighbours;
    near gaps and ends the fit uses the valid samples of a shortened window.
    Only ``sensors`` (default all) are smoothed; orientations are untouched.
    """
    names = _selected(rec, sensors)
    out = dict(rec.sensors)
    if names and rec.n_samples:
        stacked = np.stack([rec.sensors[n] for n in names], axis=1)  # (N, S, 3)
        smoothed = savgol(stacked, window, order)
        out.update({n: smoothed[:, i, :] for i, n in enumerate(names)})
    metadata = dict(rec.metadata, smoothed={"window": int(window), "order": int(order)})
    return rec.with_sensors(out, metadata=metadata)


def derivative(rec: Recording, order: int = 1, window: int | None = None, polyorder: int = 3,
               sensors=None) -> dict[str, np.ndarray]:
    """Velocity (order 1, m/s) or acceleration (order 2, m/s²) of each sensor.

    Returns {name: (N, 3) float64}.  With ``window=None`` central differences
    (``numpy.gradient``, second order inside, first order at the ends) on the
    sample times; with an odd ``window`` the derivative of the local
    Savitzky-Golay polynomial of degree ``polyorder`` (smoother, NaN-aware:
    valid neighbours only).  NaN where the derivative cannot be formed.
    """
    if order not in (1, 2):
        raise TonguevisError(f"derivative order must be 1 (velocity) or 2 (acceleration), got {order}")
    names = _selected(rec, sensors)
    if not names:
        return {}
    stacked = np.stack([rec.sensors[n] for n in names], axis=1)
    if window is not None:
        result = savgol(stacked, window, polyorder, deriv=order, delta=1.0 / rec.rate)
    else:
        if rec.n_samples < order + 1:
            raise TonguevisError(
                f"a derivative of order {order} needs at least {order + 1} samples, the recording has "
                f"{rec.n_samples}", rec.metadata.get("file"))
        result = stacked
        for _ in range(order):
            result = np.gradient(result, rec.times, axis=0)
    return {n: result[:, i, :] for i, n in enumerate(names)}
