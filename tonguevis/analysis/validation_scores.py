"""Scores for the validation: trajectory errors, return to rest, per-recording summary.

Definitions (docs/validation.md repeats them):

* RMSE (mm): sqrt(mean over frames of |p - m|²), p and m the predicted and
  measured displacement from rest (3-D); per axis sqrt(mean (p_a - m_a)²).
* Correlation: per axis, the Pearson (zero-lag) correlation of the predicted
  and measured displacement trajectories, as the cross-correlation
  coefficients of Lucero & Munhall 1999 (seed 002, Tables III-IV) and the
  coil-vertex correlation of Steiner et al. 2013 (seed 004, §3.4); the
  summary ``corr`` is their mean over the axes along which the sensor really
  moved (measured standard deviation >= ``MIN_AXIS_STD_MM``), so the lateral
  jitter of a midline sensor does not count.  A constant prediction has r = 0.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tonguevis.io.recording import Recording


MIN_AXIS_STD_MM = 1.0
REST_TOLERANCE_MM = 0.5  # sensors this close to rest count as "returned to rest"
MOVED_MM = 2.0  # ... after having moved at least this far


def pearson_axes(measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """(3,) Pearson r per axis of (F, 3) trajectories; 0 where the prediction is constant, NaN if the measurement is.

    r is clipped to [-1, 1]: for proportional trajectories the rounding of the
    quotient can otherwise give 1.0000000000000002.
    """
    m = measured - measured.mean(axis=0)
    p = predicted - predicted.mean(axis=0)
    sm = np.sqrt(np.sum(m * m, axis=0))
    sp = np.sqrt(np.sum(p * p, axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.clip(np.sum(m * p, axis=0) / (sm * sp), -1.0, 1.0)
    r = np.where(sp > 0, r, 0.0)
    return np.where(sm > 0, r, np.nan)


def trajectory_scores(measured: np.ndarray, predicted: np.ndarray) -> dict[str, Any]:
    """RMSE (mm, 3-D and per axis) and correlation (per axis and averaged) of (F, 3) trajectories in metres."""
    measured = np.asarray(measured, dtype=np.float64)
    predicted = np.asarray(predicted, dtype=np.float64)
    if measured.shape != predicted.shape or measured.ndim != 2 or measured.shape[1] != 3:
        raise ValueError(f"trajectories must both be (F, 3), got {measured.shape} and {predicted.shape}")
    if len(measured) < 2:
        return {"rmse_mm": np.nan, "rmse_axes_mm": [np.nan] * 3, "corr": np.nan, "corr_axes": [np.nan] * 3}
    err = predicted - measured
    rmse = 1e3 * np.sqrt(np.mean(np.sum(err * err, axis=1)))
    rmse_axes = 1e3 * np.sqrt(np.mean(err * err, axis=0))
    r = pearson_axes(measured, predicted)
    moving = 1e3 * measured.std(axis=0) >= MIN_AXIS_STD_MM
    chosen = r[moving] if moving.any() else r[np.isfinite(r)]
    corr = float(np.mean(chosen)) if len(chosen) else np.nan
    return {"rmse_mm": float(rmse), "rmse_axes_mm": rmse_axes.tolist(), "corr": corr, "corr_axes": r.tolist()}


def return_to_rest_frame(target_displacement: np.ndarray) -> int | None:
    """Last frame where every sensor is within REST_TOLERANCE_MM of rest after having moved MOVED_MM; None if none."""
    dist = 1e3 * np.linalg.norm(target_displacement, axis=2)  # (F, S) mm, NaN where missing
    finite = np.isfinite(dist)
    moved = np.flatnonzero(np.any(finite & (np.where(finite, dist, 0.0) > MOVED_MM), axis=1))
    if not len(moved):
        return None
    at_rest = np.flatnonzero(np.all(finite & (np.where(finite, dist, np.inf) <= REST_TOLERANCE_MM), axis=1))
    at_rest = at_rest[at_rest > moved[0]]
    return int(at_rest[-1]) if len(at_rest) else None


def recording_summary(recording: Recording, motion, prep, interval, rest_how: str) -> dict[str, Any]:
    """Per-recording figures of the full simulation (every tongue sensor driving, warped).

    Volume change (% of rest volume), sensor residuals (mm), Newton failures,
    and drift: the largest distance (mm) of any mesh node from rest at the
    last frame where every sensor target is back within 0.5 mm of rest, and
    the part of it the sensors' small offsets do not explain: the largest
    distance from the quasi-static shape for the same targets (which has no
    history).
    """
    meta = recording.metadata
    vol = 100.0 * np.asarray(motion.volume_change)
    res = 1e3 * np.asarray(motion.sensor_residual)
    rest_nodes = motion.model.mesh.points[motion.sensor_nodes]
    target_disp = np.asarray(motion.targets) - rest_nodes[None]
    frame = return_to_rest_frame(target_disp)
    drift = drift_time = drift_sensor = drift_static = None
    if frame is not None:
        disp = motion.displacements(slice(frame, frame + 1))[0]
        drift = float(1e3 * np.linalg.norm(disp, axis=1).max())
        drift_time = float(motion.times[frame])
        drift_sensor = float(1e3 * np.linalg.norm(target_disp[frame], axis=1).max())
        static = _static_shape(motion, target_disp[frame])
        drift_static = float(1e3 * np.linalg.norm(disp - static, axis=1).max())
    return {
        "file": str(meta.get("file", "")),
        "format": meta.get("format"),
        "duration_s": float(recording.duration),
        "rate_hz": float(recording.rate),
        "frames": int(recording.n_samples),
        "tongue_sensors": list(prep.names),
        "sensor_nodes": {n: int(k) for n, k in zip(prep.names, prep.nodes)},
        "ignored_sensors": list(prep.ignored),
        "rest_interval_s": [float(interval[0]), float(interval[1])],
        "rest_interval_from": rest_how,
        "alignment_scale": float(motion.metadata.get("alignment_scale", prep.transform.scale)),  # the fit, either frame
        "frame": motion.metadata.get("frame", "model"),
        "alignment_rms_mm": float(1e3 * prep.alignment_rms),
        "midsagittal_alignment": bool(prep.midsagittal),
        "volume_change_max_pct": float(np.nanmax(np.abs(vol))),
        "volume_change_mean_pct": float(np.nanmean(np.abs(vol))),
        "sensor_residual_max_mm": float(np.nanmax(res)) if np.isfinite(res).any() else None,
        "sensor_residual_mean_mm": float(np.nanmean(res)) if np.isfinite(res).any() else None,
        "unconverged_frames": int(np.sum(~np.asarray(motion.converged))),
        "drift_mm": drift,
        "drift_time_s": drift_time,
        "drift_sensor_offset_mm": drift_sensor,
        "drift_beyond_static_mm": drift_static,
        "peak_energy_mj": float(1e3 * np.nanmax(motion.energy)),
    }


def _static_shape(motion, targets: np.ndarray) -> np.ndarray:
    """(n, 3) warped quasi-static mesh displacement for one frame's sensor targets (S, 3), metres."""
    from tonguevis.analysis.quasistatic import quasi_static
    from tonguevis.sim.constrained import point_stiffness

    from tonguevis.sim.patches import global_part

    model, q_modes = global_part(motion)  # the modes' static shape (patches only close sensor gaps)
    basis = model.basis(q_modes.shape[1])
    w_full = model.rotation_matrix(basis)
    nodes = np.asarray(motion.sensor_nodes)
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    phi_s = basis.phi[dofs].reshape(len(nodes), 3, -1)
    w_s = w_full[dofs].reshape(len(nodes), 3, -1)
    # The same sensor springs as the motion (its sensor nodes follow the projected targets), else the
    # comparison would charge the springs' smoothing to drift.
    stiffness = motion.metadata.get("sensor_stiffness")
    compliance = 0.0 if stiffness is None else 1.0 / (stiffness * point_stiffness(basis.eigenvalues, phi_s))
    q, _, _ = quasi_static(basis.eigenvalues, phi_s, w_s, targets[None], compliance=compliance)
    return model.displacement(q[0], warping=True)
