"""Jaw and head correction of sensor positions (§3.1; seed 001 §3).

Jaw correction removes the jaw's translation from the tongue sensors,
S <- S - (S_J - S_J^rest) per frame, leaving the tongue's motion relative to
the jaw (the paper treats jaw motion as a rigid translation).  Head correction
removes head motion: per frame, the rigid transform that best maps the
reference sensors onto their rest pose is applied to every sensor.
"""

from __future__ import annotations


import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Recording
from tonguevis.preprocess._names import JAW, is_reference, reference_names
from tonguevis.preprocess._rigid import fit_rotations
from tonguevis.preprocess.rest import find_rest_interval, rest_pose

from tonguevis._logging import logger


def correct_jaw(rec: Recording, jaw: str = JAW, rest_interval=None, sensors=None) -> Recording:
    """Positions relative to the jaw: S <- S - (S_J - S_J^rest) for each frame.

    Applied to ``sensors`` (default: every sensor except the jaw itself and the
    head references REF*; pass ``sensors`` to leave out others that do not
    ride on the jaw, such as an upper-lip coil).  ``rest_interval`` (start_s, end_s) gives S_J^rest;
    detected with :func:`find_rest_interval` when None.  Frames where the jaw
    is invalid become NaN in the corrected sensors.
    """
    file = rec.metadata.get("file")
    if jaw not in rec.sensors:
        raise RecordingError(f"jaw correction needs a jaw sensor {jaw!r}; the recording has "
                             f"{', '.join(rec.sensor_names)}", file)
    if rest_interval is None:
        rest_interval = find_rest_interval(rec)
    jaw_rest = rest_pose(rec, rest_interval, sensors=[jaw])[jaw]
    displacement = rec.sensors[jaw] - jaw_rest  # (N, 3)
    names = [n for n in rec.sensor_names if n != jaw and not is_reference(n)] if sensors is None else sensors
    out = dict(rec.sensors)
    for name in names:
        out[name] = rec.sensors[name] - displacement
    metadata = dict(rec.metadata, jaw_corrected={"jaw": jaw, "rest_interval": list(rest_interval)})
    return rec.with_sensors(out, metadata=metadata)


def head_transforms(rec: Recording, references, reference_pose: dict[str, np.ndarray]):
    """Per-frame rigid transforms mapping the references onto ``reference_pose``.

    Returns (rotation (N, 3, 3), translation (N, 3), ok (N,) bool) such that
    ``R_i p + t_i`` moves a point of frame i into the head-fixed rest frame;
    frames with an invalid reference are not ok (rotation NaN).
    """
    current = np.stack([rec.sensors[n] for n in references], axis=1)  # (N, P, 3)
    target = np.stack([reference_pose[n] for n in references])  # (P, 3)
    ok = np.all(np.isfinite(current), axis=(1, 2))
    rotation = np.full((rec.n_samples, 3, 3), np.nan)
    translation = np.full((rec.n_samples, 3), np.nan)
    if np.any(ok):
        r, _, src_c, tgt_c, _ = fit_rotations(current[ok], np.broadcast_to(target, current[ok].shape))
        rotation[ok] = r
        translation[ok] = tgt_c - np.einsum("nij,nj->ni", r, src_c)
    return rotation, translation, ok


def correct_head(rec: Recording, references=None, rest_interval=None) -> Recording:
    """Positions in a head-fixed frame: each frame rigidly refitted on the references.

    references : names of >= 3 non-collinear head sensors (default: every
    REF* sensor).  Their rest pose (mean over ``rest_interval``, detected when
    None; the median pose over the whole recording when no rest is found)
    defines the head frame, so a still head leaves the data unchanged.
    Every sensor, the references included, is moved by the frame's rigid fit
    (vectorised Kabsch over all frames).  Quaternion orientations (N, 4;
    w, x, y, z) are rotated too; other orientation forms are dropped because
    they cannot be rotated without knowing their convention.  Frames with an
    invalid reference become NaN.
    """
    file = rec.metadata.get("file")
    references = reference_names(rec.sensor_names) if references is None else list(references)
    missing = [n for n in references if n not in rec.sensors]
    if missing:
        raise RecordingError(f"head reference(s) {', '.join(missing)} not in the recording "
                             f"(it has {', '.join(rec.sensor_names)})", file)
    if len(references) < 3:
        raise RecordingError(f"head correction needs >= 3 reference sensors, got "
                             f"{len(references)} ({', '.join(references) or 'none'})", file)
    if rest_interval is None:
        try:
            rest_interval = find_rest_interval(rec)
        except RecordingError as exc:
            rest_interval = None
            logger.info("head correction: %s; the head frame is the references' median pose instead", exc)
    if rest_interval is None:
        pose = _median_pose(rec, references)
    else:
        pose = rest_pose(rec, rest_interval, sensors=references)
    spread = np.stack([pose[n] for n in references])
    singular = np.linalg.svd(spread - spread.mean(axis=0), compute_uv=False)
    if singular[1] < 1e-3 * max(singular[0], 1e-12):
        raise RecordingError(f"head references {', '.join(references)} are collinear at rest; "
                             "a rigid fit needs three non-collinear sensors", file)
    rotation, translation, _ = head_transforms(rec, references, pose)
    sensors = {n: np.einsum("nij,nj->ni", rotation, p) + translation for n, p in rec.sensors.items()}
    orientations = {}
    for name, q in rec.orientations.items():
        if q.ndim == 2 and q.shape[1] == 4:
            orientations[name] = _rotate_quaternions(rotation, q)
    metadata = dict(rec.metadata, head_corrected={
        "references": references, "rest_interval": None if rest_interval is None else list(rest_interval)})
    return rec.with_sensors(sensors, orientations=orientations, metadata=metadata)


def _median_pose(rec: Recording, references) -> dict[str, np.ndarray]:
    pose = {}
    for name in references:
        valid = rec.sensors[name][rec.valid(name)]
        if len(valid) == 0:
            raise RecordingError(f"head reference {name} has no valid sample", rec.metadata.get("file"))
        pose[name] = np.median(valid, axis=0)
    return pose


def _rotate_quaternions(rotation: np.ndarray, q: np.ndarray) -> np.ndarray:
    """q' = q_R * q for (N, 4) quaternions (w, x, y, z); NaN rows stay NaN."""
    from scipy.spatial.transform import Rotation

    out = np.full(q.shape, np.nan)
    ok = np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(rotation), axis=(1, 2))
    if np.any(ok) and np.all(np.linalg.norm(q[ok], axis=1) > 0):
        r = Rotation.from_matrix(rotation[ok]) * Rotation.from_quat(q[ok][:, [1, 2, 3, 0]])
        xyzw = r.as_quat()
        out[ok] = xyzw[:, [3, 0, 1, 2]]
    return out


def head_corrected(rec: Recording, rest_interval=None) -> Recording:
    """``rec`` without head motion when it has >= 3 head references (REF*), else ``rec`` itself.

    The one rule every step uses (the simulation's targets, the productions):
    :func:`correct_head` on every REF* sensor, its head frame the references'
    pose over ``rest_interval`` (detected when None, else their median pose).
    """
    references = head_references(rec)
    if not references:
        return rec
    return correct_head(rec, references, rest_interval=rest_interval)


def head_references(rec: Recording) -> list[str]:
    """The head references :func:`head_corrected` uses: every REF* sensor when there are >= 3, else none."""
    references = reference_names(rec.sensor_names)
    return references if len(references) >= 3 else []


def reference_pose(corrected: Recording) -> dict[str, np.ndarray]:
    """The head references' positions (m, (3,) each) in a head-corrected recording's frame: where
    :func:`head_corrected` holds them (their median over the recording); {} without >= 3 references."""
    pose = {}
    for name in head_references(corrected):
        track = corrected.sensors[name]
        good = np.all(np.isfinite(track), axis=1)
        if good.any():
            pose[name] = np.median(track[good], axis=0)
    return pose if len(pose) >= 3 else {}


def register_references(source: dict[str, np.ndarray], target: dict[str, np.ndarray]):
    """The rigid motion carrying one sitting's head frame onto another's, from the head references
    both have: (rotation (3, 3), translation (3,) m, rms residual m, names used), or None with fewer
    than 3 shared references.  Points p of the ``source`` frame go to ``rotation @ p + translation``."""
    names = [n for n in source if n in target]
    if len(names) < 3:
        return None
    a = np.array([source[n] for n in names], dtype=np.float64)
    b = np.array([target[n] for n in names], dtype=np.float64)
    rotation, _, a_c, b_c, _ = fit_rotations(a, b)
    translation = b_c - rotation @ a_c
    residual = float(np.sqrt(np.mean(np.sum((a @ rotation.T + translation - b) ** 2, axis=1))))
    return rotation, translation, residual, names
