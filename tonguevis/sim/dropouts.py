"""Sensors that drop out and come back: bridged when short, released and re-engaged smoothly when long.

A constraint that vanishes in one frame is an impulse: on a real /ka/ a 1 s
dropout of one tongue sensor made the tongue change volume by 103 % when the
sensor's multiplier simply disappeared.  So, per sensor:

* a gap of at most ``bridge_s`` (default 0.1 s, one ramp: shorter than it takes
  to release and re-engage) is bridged by monotone cubic (PCHIP) interpolation
  of the sensor's displacement through the valid samples around it;
* a longer gap is a *release*: over the first ``ramp_s`` of the gap the sensor
  stays at its last measured position while its spring weakens to nothing;
  then it does not act; when it comes back its spring grows from nothing to
  full strength over ``ramp_s``, pulling the node from wherever the model
  carried it onto the measurement.  A sensor missing at the start engages the
  same way.

The strength is a weight w in [0, 1] per sensor and frame; the constraint's
compliance is C(w) = C₀ + (1 - w) / (w k_ramp) (m/N): C₀ at w = 1 (C₀ = 0 for
the paper's hard constraints), infinite (not acting) at w = 0.
"""

from __future__ import annotations

import numpy as np

BRIDGE_S = 0.1
RAMP_S = 0.1
#: k_ramp in units of the tongue's point stiffness at the sensors: at mid-ramp
#: (w = ½) a released hard sensor is a spring of this stiffness.
RAMP_STIFFNESS = 20.0


def bridge_short_gaps(displacement: np.ndarray, rate: float, bridge_s: float = BRIDGE_S) -> tuple[np.ndarray, int]:
    """(F, S, 3) displacements with interior gaps of at most ``bridge_s`` seconds interpolated, and the count bridged.

    Gaps at the start or end of the recording are never bridged (nothing to interpolate towards).
    """
    from scipy.interpolate import PchipInterpolator

    out = np.array(displacement, dtype=np.float64, copy=True)
    n_frames = out.shape[0]
    longest = int(np.floor(bridge_s * rate + 1e-9))
    bridged = 0
    frames = np.arange(n_frames)
    for s in range(out.shape[1]):
        valid = np.all(np.isfinite(out[:, s]), axis=1)
        if valid.all() or valid.sum() < 2:
            continue
        fill = np.zeros(n_frames, dtype=bool)
        for start, stop in _runs(~valid):
            if start > 0 and stop < n_frames and stop - start <= longest:
                fill[start:stop] = True
                bridged += 1
        if fill.any():
            out[fill, s] = PchipInterpolator(frames[valid], out[valid, s], axis=0)(frames[fill])
    return out, bridged


def engagement(valid: np.ndarray, rate: float, ramp_s: float = RAMP_S) -> tuple[np.ndarray, np.ndarray]:
    """Weights w (F, S) in [0, 1] and, per frame and sensor, the frame whose target to use (F, S) int.

    valid : (F, S) bool, the sensor measured in that frame.  During a release
    the target is the last measured frame's (held); elsewhere its own frame's.
    """
    valid = np.asarray(valid, dtype=bool)
    n_frames, n_sensors = valid.shape
    ramp = max(1, int(round(ramp_s * rate)))
    steps = np.arange(1, ramp + 1) / (ramp + 1)  # strictly inside (0, 1)
    weight = valid.astype(np.float64)
    source = np.broadcast_to(np.arange(n_frames)[:, None], (n_frames, n_sensors)).copy()
    for s in range(n_sensors):
        for start, stop in _runs(~valid[:, s]):
            if start > 0:  # release: hold the last measurement while the spring weakens
                k = min(ramp, stop - start)
                weight[start:start + k, s] = 1.0 - steps[:k]
                source[start:start + k, s] = start - 1
            if stop < n_frames:  # re-engage over the first frames back
                k = min(ramp, n_frames - stop)
                weight[stop:stop + k, s] = np.minimum(weight[stop:stop + k, s], steps[:k])
    return weight, source


def compliance_schedule(weight: np.ndarray, base: float, ramp_stiffness: float) -> np.ndarray:
    """(F, S) compliance in m/N from weights: C₀ + (1 - w)/(w k_ramp); inf where w = 0."""
    w = np.asarray(weight, dtype=np.float64)
    with np.errstate(divide="ignore"):
        comp = base + (1.0 - w) / (w * ramp_stiffness)
    return np.where(w > 0, comp, np.inf)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[(start, stop)] of the runs of True in a 1-D mask (stop exclusive)."""
    padded = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist()))
