"""Biofeedback targets: Opti-Speech's accuracy, target motion, cycles and their figures."""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.errors import TonguevisError
from tonguevis.io.recording import Recording
from tonguevis.live.targets import (
    MISSING_COLOUR, FollowingTarget, OscillatingTarget, ReplayTarget, StaticTarget, TargetError, accuracy_colour,
    accuracy_percent, cycle_period, per_cycle, score_targets, summarise, target_from_dict,
)

R = 0.004  # 4 mm


@pytest.mark.parametrize("distance, expected", [
    (0.0, 100.0), (0.5 * R, 100.0), (R, 100.0),   # inside and at the radius
    (1.25 * R, 75.0), (1.5 * R, 50.0), (1.75 * R, 25.0),  # linear between
    (2 * R, 0.0), (3 * R, 0.0), (1.0, 0.0),       # one radius outside and beyond
])
def test_accuracy_at_the_boundaries(distance, expected):
    assert accuracy_percent(distance, R) == pytest.approx(expected, abs=1e-9)


def test_accuracy_is_vectorised_and_keeps_nan():
    d = np.array([[0.0, 1.5 * R], [np.nan, 2 * R]])
    acc = accuracy_percent(d, R)
    assert acc.shape == (2, 2)
    np.testing.assert_allclose(acc[0], [100.0, 50.0])
    assert np.isnan(acc[1, 0]) and acc[1, 1] == 0.0


def test_static_target_scores_its_sensor():
    target = StaticTarget([0.01, 0.0, 0.0], R, sensor="TD")
    t = np.arange(4) * 0.01
    td = np.array([[0.01, 0, 0], [0.01 + R, 0, 0], [0.01, 1.5 * R, 0], [0.01, 0, 2.5 * R]])
    distance, acc = target.score(t, {"TD": td, "TT": np.zeros((4, 3))})
    np.testing.assert_allclose(distance, [0, R, 1.5 * R, 2.5 * R], atol=1e-12)
    np.testing.assert_allclose(acc, [100, 100, 50, 0], atol=1e-9)
    assert target.position_at(3.0).shape == (3,)
    assert target.position_at(t).shape == (4, 3)
    assert target.period is None


def test_radius_under_a_millimetre_is_refused_with_the_reason():
    with pytest.raises(TargetError, match="at least 1 mm") as info:
        StaticTarget([0, 0, 0], 0.0009)
    assert isinstance(info.value, TonguevisError)
    assert "NDI Wave" in str(info.value)
    StaticTarget([0, 0, 0], 0.001)  # 1 mm exactly is allowed
    with pytest.raises(TargetError, match="metres"):
        StaticTarget([0, 0, 0], 5.0)  # 5 mm given as 5 (metres)
    with pytest.raises(TargetError, match="opacity"):
        StaticTarget([0, 0, 0], R, opacity=1.5)


def test_oscillating_target_sine_and_linear_positions_and_period():
    a, b = np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.02])
    sine = OscillatingTarget(a, b, 2.0, R)
    assert sine.period == pytest.approx(0.5)
    p = sine.position_at([0.0, 0.125, 0.25, 0.375, 0.5, 1.25])
    np.testing.assert_allclose(p, [a, (a + b) / 2, b, (a + b) / 2, a, b], atol=1e-12)
    # An eighth of a period in: the sine eases out ((1 - cos 45 deg) / 2 = 0.146), the linear one is a quarter way.
    np.testing.assert_allclose(sine.position_at(0.0625), a + (1 - np.cos(np.pi / 4)) / 2 * (b - a), atol=1e-12)
    linear = OscillatingTarget(a, b, 2.0, R, shape="linear")
    np.testing.assert_allclose(linear.position_at(0.0625), a + 0.25 * (b - a), atol=1e-12)
    np.testing.assert_allclose(linear.position_at([0.25, 0.4375]), [b, a + 0.25 * (b - a)], atol=1e-12)
    late = OscillatingTarget(a, b, 2.0, R, start_s=0.1)
    np.testing.assert_allclose(late.position_at(0.1), a, atol=1e-12)
    with pytest.raises(TargetError, match="frequency"):
        OscillatingTarget(a, b, 0.0, R)
    with pytest.raises(TargetError, match="shape"):
        OscillatingTarget(a, b, 1.0, R, shape="square")


def test_following_target_follows_with_its_offset_and_is_missing_with_its_sensor():
    target = FollowingTarget("JAW", [0.0, 0.0, 0.01], R, sensor="TT")
    jaw = np.array([[0.0, 0.0, 0.0], [0.001, 0.0, -0.002], [np.nan, np.nan, np.nan]])
    np.testing.assert_allclose(target.position_at(np.arange(3.0), {"JAW": jaw})[:2], jaw[:2] + [0, 0, 0.01])
    tt = jaw + [0.0, 0.0, 0.01 + 1.5 * R]
    tt[2] = 0.0
    _, acc = target.score(np.arange(3.0), {"JAW": jaw, "TT": tt})
    np.testing.assert_allclose(acc[:2], [50.0, 50.0], atol=1e-9)
    assert np.isnan(acc[2])
    assert target.sensors_needed == ("TT", "JAW")
    with pytest.raises(TargetError, match="JAW"):
        target.position_at(0.0, {"TT": np.zeros(3)})


def _ramp_replay(**options) -> ReplayTarget:
    times = np.linspace(10.0, 11.0, 11)  # a production at 10-11 s on its own clock
    positions = np.column_stack([(times - 10.0) * 0.01, np.zeros(11), np.zeros(11)])  # x from 0 to 10 mm
    return ReplayTarget(times, positions, R, **options)


def test_replay_speed_reverse_offset_and_loop():
    plain = _ramp_replay()
    assert plain.period == pytest.approx(1.0)
    np.testing.assert_allclose(plain.position_at([0.0, 0.3, 1.3])[:, 0], [0.0, 0.003, 0.003], atol=1e-12)
    np.testing.assert_allclose(plain.production_time([0.0, 0.3]), [10.0, 10.3])
    fast = _ramp_replay(speed=2.0)
    assert fast.period == pytest.approx(0.5)
    np.testing.assert_allclose(fast.position_at(0.25)[0], 0.005, atol=1e-12)
    backwards = _ramp_replay(reverse=True)
    np.testing.assert_allclose(backwards.position_at([0.0, 0.1])[:, 0], [0.01, 0.009], atol=1e-12)
    shifted = _ramp_replay(offset=[0.0, 0.002, 0.0])
    np.testing.assert_allclose(shifted.position_at(0.5), [0.005, 0.002, 0.0], atol=1e-12)
    once = _ramp_replay(loop=False)
    assert once.period is None
    np.testing.assert_allclose(once.position_at(5.0)[0], 0.01, atol=1e-12)  # holds the last position
    delayed = _ramp_replay(start_s=2.0)
    np.testing.assert_allclose(delayed.position_at([1.0, 2.5])[:, 0], [0.0, 0.005], atol=1e-12)


def test_replay_ghost_template_from_a_recording():
    times = np.arange(50) / 100.0
    tt = np.column_stack([times * 0.02, np.zeros(50), np.zeros(50)])
    td = tt + [-0.02, 0.0, 0.005]
    rec = Recording(rate=100.0, times=times, sensors={"TT": tt, "TD": td})
    target = ReplayTarget.from_recording(rec, "TT", R, start_s=0.1, end_s=0.4, speed=0.5)
    assert target.times[0] == pytest.approx(0.1) and target.times[-1] == pytest.approx(0.4)
    assert target.period == pytest.approx(0.6)
    ghost = target.ghost_at([0.0, 0.2])
    assert set(ghost) == {"TT", "TD"}
    np.testing.assert_allclose(ghost["TT"], target.position_at([0.0, 0.2]))
    np.testing.assert_allclose(ghost["TD"] - ghost["TT"], [[-0.02, 0, 0.005]] * 2, atol=1e-12)
    assert target.ghost_at(0.2)["TD"].shape == (3,)
    with pytest.raises(TargetError, match="XX"):
        ReplayTarget.from_recording(rec, "XX", R)


def test_cycle_is_the_least_common_multiple_or_the_longest_period():
    a, b = np.zeros(3), np.array([0.0, 0.0, 0.01])
    two, three = OscillatingTarget(a, b, 2.0, R), OscillatingTarget(a, b, 3.0, R)
    plan = cycle_period([two, three, StaticTarget(a, R)])
    assert plan.period_s == pytest.approx(1.0) and plan.exact
    plan = cycle_period([OscillatingTarget(a, b, 1.5, R), OscillatingTarget(a, b, 1.0, R)])
    assert plan.period_s == pytest.approx(2.0) and plan.exact  # 2/3 s and 1 s repeat together every 2 s
    plan = cycle_period([OscillatingTarget(a, b, 1.0, R), OscillatingTarget(a, b, 1.01, R)])
    assert plan.period_s == pytest.approx(1.0) and not plan.exact and "100 s" in plan.reason
    plan = cycle_period([OscillatingTarget(a, b, np.pi, R), two])
    assert plan.period_s == pytest.approx(0.5) and not plan.exact and "not commensurate" in plan.reason
    plan = cycle_period([StaticTarget(a, R), _ramp_replay(loop=False)])
    assert plan.period_s is None
    assert cycle_period([_ramp_replay(speed=2.0), two]).period_s == pytest.approx(0.5)


def test_per_cycle_figures_on_a_hand_built_accuracy():
    t = np.arange(250) / 100.0  # 2.5 s at 100 Hz: two whole cycles of 1 s and half of a third
    acc = np.empty(250)
    acc[:50], acc[50:100] = 100.0, 0.0        # cycle 1: half hit, half missed -> 50 %
    acc[100:200] = 80.0
    acc[150:160] = np.nan                     # cycle 2: 10 samples missing -> 80 % over 90
    acc[200:] = 20.0
    cycles = per_cycle(t, acc, 1.0)
    assert [c.index for c in cycles] == [0, 1, 2]
    assert [c.complete for c in cycles] == [True, True, False]
    first, second, third = (c.targets[0] for c in cycles)
    assert first.mean_percent == pytest.approx(50.0) and first.hit_fraction == pytest.approx(0.5)
    assert (first.n_samples, first.n_missing) == (100, 0)
    assert second.mean_percent == pytest.approx(80.0) and second.hit_fraction == 0.0
    assert (second.n_samples, second.n_missing) == (90, 10)
    assert third.mean_percent == pytest.approx(20.0) and third.n_samples == 50
    assert cycles[1].start_s == pytest.approx(1.0) and cycles[1].end_s == pytest.approx(2.0)


def test_a_still_sensor_against_a_sine_target_scores_the_known_mean():
    """Sensor still at a; the target swings to b = a + 2r: inside half the time, then 100 (1 + cos) %.

    Over a cycle the mean is 50 + 50 (1 - 2/pi) = 100 (1 - 1/pi) = 68.17 %.
    """
    a = np.array([0.0, 0.0, 0.0])
    target = OscillatingTarget(a, a + [2 * R, 0, 0], 1.0, R)
    t = np.arange(2000) / 1000.0  # two cycles at 1 kHz
    sensors = {"TT": np.zeros((2000, 3))}
    distance, acc = score_targets([target], t, sensors)
    assert distance.shape == acc.shape == (2000, 1)
    cycles = per_cycle(t, acc, cycle_period([target]).period_s)
    assert len(cycles) == 2 and all(c.complete for c in cycles)
    for c in cycles:
        assert c.targets[0].mean_percent == pytest.approx(100 * (1 - 1 / np.pi), abs=0.05)
        assert c.targets[0].hit_fraction == pytest.approx(0.5, abs=0.002)
    assert summarise(acc[:, 0]).mean_percent == pytest.approx(100 * (1 - 1 / np.pi), abs=0.05)


def test_missing_samples_are_left_out_and_counted():
    s = summarise([100.0, np.nan, 50.0, np.nan, 0.0])
    assert s.mean_percent == pytest.approx(50.0)
    assert (s.n_samples, s.n_missing) == (3, 2)
    empty = summarise([np.nan, np.nan])
    assert np.isnan(empty.mean_percent) and (empty.n_samples, empty.n_missing) == (0, 2)
    assert empty.to_dict()["mean_percent"] is None  # JSON has no NaN


def test_colour_runs_from_red_to_green_and_grey_when_missing():
    rgb = accuracy_colour([0.0, 50.0, 100.0, np.nan, 150.0])
    np.testing.assert_allclose(rgb[:3], [[1, 0, 0], [1, 1, 0], [0, 1, 0]])
    np.testing.assert_allclose(rgb[3], MISSING_COLOUR)
    np.testing.assert_allclose(rgb[4], [0, 1, 0])
    assert accuracy_colour(25.0).shape == (3,)
    assert np.all((rgb >= 0) & (rgb <= 1))


def test_every_kind_survives_its_dict():
    a, b = np.zeros(3), np.array([0.0, 0.01, 0.0])
    replay = _ramp_replay(speed=1.5, reverse=True, offset=[0, 0, 0.001], start_s=0.2)
    replay.positions[3] = np.nan
    targets = [StaticTarget(b, R, sensor="TD", opacity=0.3, name="palate"),
               OscillatingTarget(a, b, 1.5, R, shape="linear", start_s=0.3),
               FollowingTarget("JAW", b, R), replay]
    t = np.linspace(0, 2, 17)
    sensors = {"JAW": np.random.default_rng(0).normal(size=(17, 3)) * 0.01}
    for target in targets:
        back = target_from_dict(target.to_dict())
        assert type(back) is type(target)
        assert (back.sensor, back.radius, back.opacity, back.name) == (target.sensor, target.radius, target.opacity,
                                                                       target.name)
        np.testing.assert_array_equal(back.position_at(t, sensors), target.position_at(t, sensors))
    with pytest.raises(TargetError, match="unknown target kind"):
        target_from_dict({"kind": "pyramid"})
    with pytest.raises(TargetError, match="radius_m"):
        target_from_dict({"kind": "static", "sensor": "TT", "point_m": [0, 0, 0]})
