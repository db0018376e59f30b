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


def _moving_recording(still_from: float, still_to: float, duration: float = 2.0):
    """Speech-like motion everywhere but a short still stretch ``still_from``-``still_to`` s."""
    from tonguevis.io.recording import Recording

    rate = 100.0
    t = np.arange(int(duration * rate)) / rate
    frozen = np.clip(t, None, still_from) + np.clip(t - still_to, 0, None)  # clock that stops while still
    tip = np.stack([0.005 * np.sin(9 * frozen), 0 * t, 0.004 * np.cos(7 * frozen)], axis=1)
    return Recording(rate=rate, times=t, sensors={"TT": tip, "TD": 0.5 * tip + 0.01}, metadata={"file": "x.tsv"})


def test_the_rest_falls_back_to_the_stillest_window_and_says_so(caplog):
    from tonguevis.preprocess import RestChoice, choose_rest_interval, stillest_window

    rec = _moving_recording(1.2, 1.5)
    with caplog.at_level("WARNING", logger="tonguevis"):
        choice = choose_rest_interval(rec, ["TT", "TD"])
    assert choice.how == "stillest window" and choice.reason == "no still second in the recording"
    assert 1.2 - 1e-9 <= choice.interval[0] and choice.interval[1] <= 1.5 + 0.011
    assert stillest_window(rec, ["TT"]) == choice.interval
    assert "the stillest 0.2 s" in caplog.text and "x.tsv" in caplog.text
    assert choice.describe() == (f"rest: {choice.interval[0]:.2f}-{choice.interval[1]:.2f} s "
                                 "(stillest window: no still second in the recording)")
    assert RestChoice.from_dict(choice.as_dict()) == choice
    given = choose_rest_interval(rec, ["TT"], (0.1, 0.3))
    assert given == RestChoice((0.1, 0.3), "given") and given.describe() == "rest: 0.10-0.30 s (given)"


def test_a_detected_rest_is_reported_as_detected():
    from tonguevis.preprocess import choose_rest_interval

    choice = choose_rest_interval(moving_recording())
    assert choice.how == "detected" and choice.interval[0] < 0.1 and 3.8 <= choice.interval[1] <= 4.05
    assert choice.describe().endswith("(detected: the longest still stretch)")


def test_a_recording_under_a_second_gets_the_stillest_window():
    from tonguevis.preprocess import choose_rest_interval

    choice = choose_rest_interval(_moving_recording(0.3, 0.5, duration=0.8))
    assert choice.how == "stillest window" and choice.reason == "the recording is shorter than a second"


@pytest.mark.parametrize("given, problem", [
    ((3.0, 2.0), "the end must come after the start"),
    ((1.0, 1.0), "the end must come after the start"),
    ((1.5, 2.5), "not inside the recording (0.00-1.99 s)"),
    ((-1.0, 0.5), "not inside the recording"),
    ((float("nan"), 0.5), "finite"),
    (("a", "b"), "two numbers"),
])
def test_a_bad_given_rest_names_the_problem_and_the_file(given, problem):
    from tonguevis.preprocess import choose_rest_interval

    with pytest.raises(RecordingError, match="x.tsv") as info:
        choose_rest_interval(_moving_recording(1.2, 1.5), given=given)
    assert problem in str(info.value)


def test_a_given_rest_needs_valid_samples_of_every_sensor():
    from tonguevis.preprocess import choose_rest_interval

    rec = _moving_recording(1.2, 1.5)
    rec.sensors["TD"][:60] = np.nan
    with pytest.raises(RecordingError, match="no valid sample of TD"):
        choose_rest_interval(rec, given=(0.1, 0.5))
    assert choose_rest_interval(rec, given=(0.1, 0.8)).interval == (0.1, 0.8)


def test_the_no_rest_message_says_how_to_give_one():
    t = np.arange(500) / 100.0
    tip = np.column_stack([0.01 * np.sin(2 * np.pi * t)] * 3)
    with pytest.raises(RecordingError, match="--rest START END") as info:
        find_rest_interval(recording({"TT": tip}))
    assert "Set rest interval" in str(info.value) and "explicitly" not in str(info.value)
