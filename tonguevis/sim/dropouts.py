"""Sensors that drop out and come back: bridged when short, handed over to the model smoothly when long.

A constraint that vanishes in one frame is an impulse: on a real /ka/, one
tongue sensor lost for 1 s made the tongue change volume by 103 % when its
multiplier simply disappeared.  So, per sensor:

* a gap of at most ``bridge_s`` (default 0.1 s, one ramp: shorter than it takes
  to hand a sensor over and back) is bridged by monotone cubic (PCHIP)
  interpolation of its displacement through the valid samples around it;
* a longer gap is handed over to the model in the *projection* of the targets
  onto the tongue's deformations (:func:`tonguevis.sim.constrained.compliant_targets`),
  where each sensor is a spring: over the first ``ramp_s`` of the gap the lost
  sensor's spring, anchored at its last measurement, weakens to nothing
  (weight w from 1 to 0), so every sensor's projected target, its own and the
  others', moves smoothly from what the measurements said to what the other
  sensors say; then it does not act.  When it comes back its spring grows
  from nothing to full strength over ``ramp_s``, moving its target from where
  the others put its node onto its measurement.  A sensor missing at the
  start engages the same way.  The dynamic solve holds the acting sensor
  nodes to the projected targets.

A spring of weight w has compliance C(w) = C₀ + (1 - w) / (w k_ramp) (m/N):
C₀ at w = 1 (C₀ = 0 for the paper's hard constraints), infinite at w = 0.
(Tried and dropped: weakening the spring in the dynamic solve, fading the
sensor's last force, or blending held targets with a prediction outside the
projection: each left a step in the force or in the other sensors' targets,
an impulse that on the real /ka/ and /ta/ ran away or kicked the energy up.)
"""

from __future__ import annotations

import numpy as np

BRIDGE_S = 0.1
RAMP_S = 0.1
#: k_ramp in units of the tongue's point stiffness at the sensors (see
#: :func:`tonguevis.sim.constrained.point_stiffness`): the spring at mid-ramp.
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
    """Spring weights (F, S) in [0, 1] and, per frame and sensor, the frame whose measurement anchors it (F, S).

    valid : (F, S) bool, the sensor measured in that frame.  w = 1 where
    measured (ramping up from 0 over the first ``ramp_s`` back), falling from
    1 to 0 over the first ``ramp_s`` of a gap (anchored at the last
    measurement), 0 elsewhere in gaps.
    """
    valid = np.asarray(valid, dtype=bool)
    n_frames, n_sensors = valid.shape
    ramp = max(1, int(round(ramp_s * rate)))
    steps = np.arange(1, ramp + 1) / (ramp + 1)  # strictly inside (0, 1)
    weight = valid.astype(np.float64)
    source = np.broadcast_to(np.arange(n_frames)[:, None], (n_frames, n_sensors)).copy()
    for s in range(n_sensors):
        for start, stop in _runs(~valid[:, s]):
            if start > 0:  # release: the spring at the last measurement weakens
                k = min(ramp, stop - start)
                weight[start:start + k, s] = 1.0 - steps[:k]
                source[start:start + k, s] = start - 1
            if stop < n_frames:  # back: the spring grows
                k = min(ramp, n_frames - stop)
                weight[stop:stop + k, s] = np.minimum(weight[stop:stop + k, s], steps[:k])
    return weight, source


def spring_compliance(weight: np.ndarray, base: float, ramp_stiffness: float) -> np.ndarray:
    """(F, S) compliance in m/N from spring weights: C₀ + (1 - w)/(w k_ramp); inf where w = 0."""
    w = np.asarray(weight, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        comp = base + (1.0 - w) / (w * ramp_stiffness)
    return np.where(w > 0, comp, np.inf)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[(start, stop)] of the runs of True in a 1-D mask (stop exclusive)."""
    padded = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist()))
