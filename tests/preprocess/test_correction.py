"""Jaw and head correction undo known motion; the vectorised Kabsch equals a per-frame loop."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.preprocess._synthetic import random_rotations, recording
from tonguevis.errors import RecordingError
from tonguevis.preprocess import correct_head, correct_jaw, fit_similarity
from tonguevis.preprocess._rigid import fit_rotations

REST = {"TT": [0.0, 0.0, 0.0], "TD": [-0.02, 0.0, 0.005], "TL": [-0.01, 0.006, 0.003],
        "JAW": [0.005, 0.0, -0.012], "REF1": [-0.085, 0.062, -0.018], "REF2": [0.022, 0.0, 0.048],
        "REF3": [-0.001, 0.0, 0.009]}


def head_frame_motion(n=600, seed=0):
    """Still 0-2 s; tongue and jaw move afterwards. Positions in the head frame (m)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    moving = (t > 2.0).astype(float)
    jaw = np.column_stack([-0.002 * np.sin(3 * t), 0 * t, -0.007 * (1 - np.cos(4 * t))]) * moving[:, None]
    tongue = {name: np.asarray(p) + rng.normal(0, 1e-3, 3) * np.sin(5 * t)[:, None] * moving[:, None]
              for name, p in REST.items() if name in ("TT", "TD", "TL")}
    return t, jaw, tongue


def test_jaw_correction_removes_the_jaw_translation():
    t, jaw, tongue = head_frame_motion()
    sensors = {name: p + jaw for name, p in tongue.items()}  # tongue rides on the jaw
    sensors["JAW"] = np.asarray(REST["JAW"]) + jaw
    sensors["REF1"] = np.tile(REST["REF1"], (len(t), 1))
    sensors["JAW"][300] = np.nan
    rec = recording(sensors)
    out = correct_jaw(rec, rest_interval=(0.0, 1.9))
    for name in tongue:
        ok = np.arange(len(t)) != 300
        np.testing.assert_allclose(out.sensors[name][ok], tongue[name][ok], atol=1e-12)
        assert np.all(np.isnan(out.sensors[name][300]))
    np.testing.assert_array_equal(out.sensors["JAW"], rec.sensors["JAW"])  # the jaw keeps its motion
    np.testing.assert_array_equal(out.sensors["REF1"], rec.sensors["REF1"])
    with pytest.raises(RecordingError, match="jaw sensor"):
        correct_jaw(recording({"TT": tongue["TT"]}), rest_interval=(0, 1))


def device_frame(positions: dict, rotation: Rotation, shift: np.ndarray) -> dict:
    pivot = np.array([-0.08, 0.0, -0.06])
    return {n: rotation.apply(p - pivot) + pivot + shift for n, p in positions.items()}


def test_head_correction_undoes_known_head_motion():
    t, jaw, tongue = head_frame_motion()
    head = {name: p + jaw for name, p in tongue.items()}
    head["JAW"] = np.asarray(REST["JAW"]) + jaw
    for name in ("REF1", "REF2", "REF3"):
        head[name] = np.tile(REST[name], (len(t), 1))
    # Head still during the rest (0-2 s), then it nods up to 5 degrees and shifts 3 mm.
    ramp = np.clip(t - 2.0, 0, None)
    rotation = Rotation.from_rotvec(np.column_stack([0.02 * ramp, 0.09 * np.sin(ramp), -0.03 * ramp]))
    shift = np.column_stack([0.003 * np.sin(ramp), 0.001 * ramp, -0.002 * ramp])
    rec = recording(device_frame(head, rotation, shift))
    rec.sensors["REF2"][400] = np.nan
    out = correct_head(rec)
    ok = np.arange(len(t)) != 400
    for name in head:
        np.testing.assert_allclose(out.sensors[name][ok], head[name][ok], atol=1e-10)
        assert np.all(np.isnan(out.sensors[name][400]))
    # and the jaw correction then recovers the tongue alone
    jaw_free = correct_jaw(out, rest_interval=(0.0, 1.9))
    np.testing.assert_allclose(jaw_free.sensors["TT"][ok], tongue["TT"][ok], atol=1e-10)


def test_head_correction_rotates_quaternions():
    n = 300
    still = {name: np.tile(p, (n, 1)) for name, p in REST.items()}
    rotation = Rotation.from_rotvec(np.column_stack([np.linspace(0, 0.2, n), np.zeros(n), np.zeros(n)]))
    rec = recording(device_frame(still, rotation, np.zeros((n, 3))))
    sensor_q = Rotation.from_euler("z", 30, degrees=True)
    device_q = (rotation * sensor_q).as_quat()[:, [3, 0, 1, 2]]  # (w, x, y, z)
    rec.orientations["TT"] = device_q
    out = correct_head(rec, rest_interval=(0.0, 0.0))
    expected = np.tile(sensor_q.as_quat()[[3, 0, 1, 2]], (n, 1))
    got = out.orientations["TT"]
    np.testing.assert_allclose(np.abs(np.sum(got * expected, axis=1)), 1.0, atol=1e-9)  # q ~ -q


def reference_kabsch(source: np.ndarray, target: np.ndarray):
    """One frame at a time, textbook Kabsch with the reflection fix."""
    a = source - source.mean(axis=0)
    b = target - target.mean(axis=0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1, 1, d]) @ u.T


def test_batched_kabsch_equals_loop():
    rng = np.random.default_rng(5)
    source = rng.normal(size=(50, 4, 3))
    true = random_rotations(rng, 50)
    target = np.einsum("nij,npj->npi", true, source) + rng.normal(size=(50, 1, 3))
    target += rng.normal(0, 0.05, target.shape)  # not exact: the fit must be least squares
    rotation, scale, _, _, _ = fit_rotations(source, target)
    for i in range(50):
        np.testing.assert_allclose(rotation[i], reference_kabsch(source[i], target[i]), atol=1e-10)
    np.testing.assert_allclose(np.linalg.det(rotation), 1.0)
    assert np.all(np.abs(scale - 1) < 0.1)


def test_head_correction_needs_three_references():
    rec = recording({n: np.tile(p, (200, 1)) for n, p in REST.items() if n != "REF3"})
    with pytest.raises(RecordingError, match=">= 3 reference"):
        correct_head(rec)
    line = {n: np.tile([0.01 * k, 0, 0], (200, 1)) for k, n in enumerate(["REF1", "REF2", "REF3"])}
    line["TT"] = np.zeros((200, 3))
    with pytest.raises(RecordingError, match="collinear"):
        correct_head(recording(line))


def test_head_correction_without_rest_uses_the_median_pose():
    """No still interval: the head frame is the references' median pose; the motion is still removed."""
    n = 400
    t = np.arange(n) / 100.0
    tongue = np.column_stack([0.01 * np.sin(6 * t), 0 * t, 0.008 * np.cos(7 * t)])  # never still
    head = {"TT": tongue, **{r: np.tile(REST[r], (n, 1)) for r in ("REF1", "REF2", "REF3")}}
    rotation = Rotation.from_rotvec(np.column_stack([0 * t, 0.05 * np.sin(2 * t), 0 * t]))
    rec = recording(device_frame(head, rotation, np.zeros((n, 3))))
    out = correct_head(rec)
    assert out.metadata["head_corrected"]["rest_interval"] is None
    # the result is the head-frame motion up to one fixed rigid transform G
    for r in ("REF1", "REF2", "REF3"):
        np.testing.assert_allclose(np.ptp(out.sensors[r], axis=0), 0, atol=1e-12)
    refs = ("REF1", "REF2", "REF3")
    g = fit_similarity(np.array([REST[r] for r in refs]), np.array([out.sensors[r][0] for r in refs]))
    assert g.scale == pytest.approx(1.0)
    np.testing.assert_allclose(out.sensors["TT"], g.apply(tongue), atol=1e-12)
