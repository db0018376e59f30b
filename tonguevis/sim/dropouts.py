"""Sensors that drop out and come back: bridged when short, handed over to the model smoothly when long.

A constraint that vanishes in one frame is an impulse: on a real /ka/, one
tongue sensor lost for 1 s made the tongue change volume by 103 % when its
multiplier simply disappeared (the nodes it held snapped by several radians
in one frame).  So, per sensor:

* a gap of at most ``bridge_s`` (default 0.1 s, one ramp: shorter than it takes
  to hand a sensor over and back) is bridged by monotone cubic (PCHIP)
  interpolation of its displacement through the valid samples around it;
* over a longer gap the model itself says where that sensor's node goes: the
  position the other sensors give it (:func:`tonguevis.sim.constrained.compliant_targets`
  leaves the missing sensor out and returns every node's displacement).  For
  the first ``ramp_s`` of the gap the node's target moves from its last
  measured position onto that prediction, then the constraint is released;
  since the node is by then where the tongue takes it anyway, releasing it
  takes almost no force away.  When the sensor comes back, its target moves
  from the prediction onto the measurement over ``ramp_s``.  A sensor missing
  at the start engages the same way.

(Fading the sensor's last force, or weakening it into a spring, was tried
first: with the paper's hard constraints the last force is large, and the
Newton solve of the first released frame ran away onto several-radian
rotations on that same /ka/; a spring, at the first released frame, still sits
on its target and pulls with nothing, which is the impulse again.)
"""

from __future__ import annotations

import numpy as np

BRIDGE_S = 0.1
RAMP_S = 0.1


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


def handover(valid: np.ndarray, rate: float, ramp_s: float = RAMP_S) -> tuple[np.ndarray, np.ndarray]:
    """How much each sensor's target trusts its measurement, and whether it acts.

    valid : (F, S) bool, the sensor measured in that frame.  Returns
    ``trust`` (F, S) in [0, 1] (1: the measurement; 0: the model's prediction;
    in between: a blend, with the last measured frame standing in during a
    release) and ``acting`` (F, S) bool (measured, or within ``ramp_s`` after
    the last measurement).
    """
    valid = np.asarray(valid, dtype=bool)
    n_frames, n_sensors = valid.shape
    ramp = max(1, int(round(ramp_s * rate)))
    steps = np.arange(1, ramp + 1) / (ramp + 1)  # strictly inside (0, 1)
    trust = valid.astype(np.float64)
    acting = valid.copy()
    for s in range(n_sensors):
        for start, stop in _runs(~valid[:, s]):
            if start > 0:  # release: onto the prediction, then let go
                k = min(ramp, stop - start)
                trust[start:start + k, s] = 1.0 - steps[:k]
                acting[start:start + k, s] = True
            if stop < n_frames:  # back: from the prediction onto the measurement
                k = min(ramp, n_frames - stop)
                trust[stop:stop + k, s] = np.minimum(trust[stop:stop + k, s], steps[:k])
    return trust, acting


def blend_targets(measured: np.ndarray, predicted: np.ndarray, trust: np.ndarray, acting: np.ndarray) -> np.ndarray:
    """(F, S, 3) targets: trust·measured + (1 - trust)·predicted where acting, NaN elsewhere.

    During a release (no measurement) the last measured value stands in.
    """
    held = _hold_last(measured)
    base = np.where(np.isfinite(measured), measured, held)
    t = trust[:, :, None]
    out = t * np.nan_to_num(base) + (1.0 - t) * predicted
    out = np.where((t == 0) | np.isfinite(base), out, np.nan)
    return np.where(acting[:, :, None], out, np.nan)


def _hold_last(x: np.ndarray) -> np.ndarray:
    """(F, S, 3) with every NaN sample replaced by the sensor's last finite one (NaN before the first)."""
    finite = np.all(np.isfinite(x), axis=2)
    idx = np.where(finite, np.arange(len(x))[:, None], -1)
    idx = np.maximum.accumulate(idx, axis=0)
    out = x[np.maximum(idx, 0), np.arange(x.shape[1])[None, :]]
    return np.where((idx >= 0)[:, :, None], out, np.nan)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[(start, stop)] of the runs of True in a 1-D mask (stop exclusive)."""
    padded = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist()))
