"""Rest interval detection and rest pose."""

import numpy as np
import pytest

from tests.preprocess._synthetic import recording
from tonguevis.errors import RecordingError
from tonguevis.preprocess import find_rest_interval, rest_pose
from tonguevis.preprocess.rest import longest_run


def moving_recording(seed=0):
    """Rest 0-4 s, speech-like motion 4-8 s, a short pause 8-9.5 s, motion again to 12 s."""
    rng = np.random.default_rng(seed)
    t = np.arange(1200) / 100.0
    z = np.where((t >= 4) & (t < 8), 0.006 * np.sin(2 * np.pi * 3.5 * (t - 4)), 0.0)
    z += np.where(t >= 9.5, 0.006 * np.sin(2 * np.pi * 3.5 * (t - 9.5)), 0.0)
    tip = np.column_stack([np.zeros_like(t), np.zeros_like(t), z]) + [0.01, 0.0, 0.02]
    tip = tip + rng.normal(0, 2e-4, tip.shape)  # 0.2 mm noise
    ref = np.tile([0.05, 0.0, 0.05], (len(t), 1)) + rng.normal(0, 2e-4, tip.shape)
    return recording({"TT": tip, "TD": tip - [0.02, 0, 0], "REF1": ref})


def test_longest_run():
    assert longest_run(np.array([0, 1, 1, 0, 1, 1, 1, 0], bool)) == (4, 6)
    assert longest_run(np.zeros(4, bool)) == (0, -1)
    assert longest_run(np.ones(3, bool)) == (0, 2)


def test_finds_the_initial_rest_not_the_pause():
    rec = moving_recording()
    start, end = find_rest_interval(rec)
    assert start < 0.1
    assert 3.8 <= end <= 4.05  # the motion starts at 4 s


def test_invalid_samples_break_stillness():
    rec = moving_recording()
    rec.sensors["TT"][150] = np.nan  # at 1.5 s: the longest rest is now 1.51-4 s
    start, end = find_rest_interval(rec)
    assert 1.5 < start <= 1.52 and 3.8 <= end <= 4.05


def test_rest_pose_is_the_mean_over_the_interval():
    rec = moving_recording()
    rec.sensors["TD"][10] = np.nan
    pose = rest_pose(rec, (0.0, 3.0))
    np.testing.assert_allclose(pose["TT"], rec.sensors["TT"][:301].mean(axis=0))
    ok = np.isfinite(rec.sensors["TD"][:301, 0])
    np.testing.assert_allclose(pose["TD"], rec.sensors["TD"][:301][ok].mean(axis=0))
    np.testing.assert_allclose(pose["TT"], [0.01, 0.0, 0.02], atol=5e-5)


def test_no_rest_raises():
    t = np.arange(500) / 100.0
    tip = np.column_stack([0.01 * np.sin(2 * np.pi * t)] * 3)
    with pytest.raises(RecordingError, match="no still interval"):
        find_rest_interval(recording({"TT": tip}))
    with pytest.raises(RecordingError, match="missing TX"):
        find_rest_interval(recording({"TT": tip}), sensors=["TX"])
    with pytest.raises(RecordingError, match="no valid sample"):
        rest_pose(recording({"TT": np.full((50, 3), np.nan)}), (0.0, 0.3))
