"""Patient profiles: a JSON round trip of everything a session sets up, and clear errors on bad files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tonguevis.errors import TonguevisError
from tonguevis.live.profiles import (
    SCHEMA_VERSION, Profile, ProfileError, RestPose, SweepRecord, apply_sensor_offsets, list_profiles, load_profile,
    profile_path, profiles_dir, save_profile,
)
from tonguevis.live.targets import FollowingTarget, OscillatingTarget, ReplayTarget, StaticTarget

R = 0.003


def _profile() -> Profile:
    replay_positions = np.column_stack([np.linspace(0, 0.01, 5), np.zeros(5), np.zeros(5)])
    replay_positions[2] = np.nan
    targets = [StaticTarget([0.01, 0.0, 0.02], R, sensor="TT", opacity=0.4, name="alveolar ridge"),
               OscillatingTarget([0, 0, 0], [0, 0, 0.01], 1.5, R, sensor="TD"),
               FollowingTarget("JAW", [0.0, 0.0, 0.012], R),
               ReplayTarget(np.arange(5) / 100.0, replay_positions, R, speed=0.5, reverse=True,
                            template={"TD": replay_positions - [0.02, 0, 0]})]
    return Profile(
        "pt-007", "Patient seven", targets=targets,
        sensor_offsets={"TT": [0.01, 0.0, 0.0]},
        rest=RestPose({"TT": np.array([0.0, 0.0, -0.01]), "TD": np.array([-0.02, 0.0, -0.005])}, (1.5, 2.5)),
        sensor_map={"REF1": 0, "TT": 1, "TD": 2, "JAW": 5}, axes="-y,x,z",
        sweeps=[SweepRecord(1, "ta x10", "sweeps/001_ta_x10", "2026-12-03T10:00:00+00:00", 12.5, 1250,
                            [{"target": "alveolar ridge", "sensor": "TT", "mean_percent": 71.5, "hit_fraction": 0.5,
                              "n_samples": 1240, "n_missing": 10}])],
        notes="sensor TT glued 10 mm back")


def test_profile_round_trip(tmp_path):
    profile = _profile()
    path = save_profile(profile, tmp_path)
    assert path == tmp_path / "pt-007" / "profile.json" == profile_path("pt-007", tmp_path)
    assert [p.name for p in path.parent.iterdir()] == ["profile.json"]  # no temporary file left
    data = json.loads(path.read_text())
    assert data["schema_version"] == SCHEMA_VERSION and data["units"]["positions"] == "m"
    back = load_profile("pt-007", tmp_path)
    assert (back.id, back.name, back.notes, back.axes) == ("pt-007", "Patient seven", profile.notes, "-y,x,z")
    assert back.sensor_map == profile.sensor_map
    np.testing.assert_array_equal(back.sensor_offsets["TT"], [0.01, 0.0, 0.0])
    assert back.rest.interval_s == (1.5, 2.5) and back.rest.taken == profile.rest.taken
    np.testing.assert_array_equal(back.rest.positions["TD"], profile.rest.positions["TD"])
    assert back.sweeps == profile.sweeps
    t = np.linspace(0, 3, 31)
    sensors = {"JAW": np.random.default_rng(1).normal(size=(31, 3)) * 0.01}
    assert [type(x) for x in back.targets] == [type(x) for x in profile.targets]
    for a, b in zip(profile.targets, back.targets):
        assert (a.name, a.sensor, a.radius, a.opacity) == (b.name, b.sensor, b.radius, b.opacity)
        np.testing.assert_array_equal(a.position_at(t, sensors), b.position_at(t, sensors))
    np.testing.assert_array_equal(back.targets[3].template["TD"], profile.targets[3].template["TD"])
    # The path of the file (or its folder) opens it too; the next sweep follows the last.
    assert load_profile(path).id == load_profile(path.parent).id == "pt-007"
    assert back.next_sweep_number() == 2
    assert back.sweep_folder(2, "ka / slow", tmp_path) == tmp_path / "pt-007" / "sweeps" / "002_ka_slow"
    assert list_profiles(tmp_path) == ["pt-007"]


def test_malformed_json_names_the_file(tmp_path):
    path = save_profile(_profile(), tmp_path)
    path.write_text('{"kind": "tonguevis live profile", "schema_version": 1,')
    with pytest.raises(ProfileError, match="malformed JSON at line 1") as info:
        load_profile(path)
    assert str(path) in str(info.value) and isinstance(info.value, TonguevisError)


@pytest.mark.parametrize("change, message", [
    (lambda d: d.update(kind="something else"), "not a tonguevis live profile"),
    (lambda d: d.update(schema_version=SCHEMA_VERSION + 1), "newer tonguevis"),
    (lambda d: d["targets"][1].pop("frequency_hz"), r"targets\[1\].*frequency_hz"),
    (lambda d: d["targets"][0].update(radius_m=0.0005), r"targets\[0\].*at least 1 mm"),
    (lambda d: d.update(id="../escape"), "profile id"),
    (lambda d: d["sensor_map"]["sensors"].update(TD=1), "same slot"),
    (lambda d: d["sweeps"][0].pop("number"), "sweeps.*number"),
])
def test_wrong_profiles_are_refused_with_the_file_and_the_field(tmp_path, change, message):
    path = save_profile(_profile(), tmp_path)
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))
    with pytest.raises(ProfileError, match=message) as info:
        load_profile(path)
    assert str(path) in str(info.value)


def test_missing_profile_and_bad_id(tmp_path):
    with pytest.raises(ProfileError, match="no such profile file"):
        load_profile("nobody", tmp_path)
    with pytest.raises(ProfileError, match="profile id"):
        Profile("a b/c")
    assert list_profiles(tmp_path / "absent") == []


def test_default_folder_is_the_users_data_dir_or_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("TONGUEVIS_PROFILES", raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    import sys
    if sys.platform.startswith("linux"):
        assert profiles_dir() == tmp_path / "data" / "tonguevis" / "profiles"
    monkeypatch.setenv("TONGUEVIS_PROFILES", str(tmp_path / "p"))
    assert profiles_dir() == tmp_path / "p"
    save_profile(Profile("x1"))
    assert load_profile("x1").id == "x1" and (tmp_path / "p" / "x1" / "profile.json").is_file()


def test_sensor_offsets_are_added_to_their_sensor_only():
    sensors = {"TT": np.zeros((2, 3)), "TD": np.ones((2, 3))}
    out = apply_sensor_offsets(sensors, {"TT": [0.01, 0.0, 0.0]})
    np.testing.assert_array_equal(out["TT"], [[0.01, 0, 0]] * 2)
    np.testing.assert_array_equal(out["TD"], sensors["TD"])
