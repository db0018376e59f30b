"""Sensor maps: presets, JSON files, dicts, and what is refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.io.synthetic import make_recording
from tonguevis.io import RecordingError, load_sensor_map, read_recording, write_recording
from tonguevis.io.sensor_map import PRESET_DIR, preset_names


def test_presets_are_documented_and_valid():
    assert set(preset_names()) >= {"paper", "haskins", "mngu0"}
    for name in preset_names():
        data = json.loads((PRESET_DIR / f"{name}.json").read_text())
        assert len(data["description"]) > 40
        mapping = load_sensor_map(name)
        assert mapping == data["sensors"]
        assert set(mapping.optional) <= set(mapping)
    assert load_sensor_map("haskins")["TBK"] == "TR"  # Haskins' tongue rear is our TBK
    assert load_sensor_map("mngu0") == {"TT": "T1", "TB": "T2", "TD": "T3", "JAW": "jaw"}
    paper = load_sensor_map("paper")
    assert {paper[k] for k in ("TT", "TD", "TL", "TR", "JAW")} == {1, 2, 3, 4, 5}


def test_json_file_and_dict(tmp_path):
    plain = tmp_path / "plain.json"
    plain.write_text(json.dumps({"TT": 3, "JAW": "S7"}))
    assert load_sensor_map(plain) == {"TT": 3, "JAW": "S7"}
    assert load_sensor_map(str(plain)) == {"TT": 3, "JAW": "S7"}
    assert load_sensor_map({"TT": "CH5"}) == {"TT": "CH5"}


@pytest.mark.parametrize("content, message", [
    ("{not json", "not valid JSON"),
    ('["TT"]', "must be an object"),
    ('{"TT": 1, "TD": 1}', "mapped to more than one name"),
    ('{"TT": [1]}', "must be a name or a number"),
    ('{"sensors": {"TT": 1}, "optional": "TT"}', "'optional' must be a list"),
])
def test_bad_maps(tmp_path, content, message):
    path = tmp_path / "map.json"
    path.write_text(content)
    with pytest.raises(RecordingError, match=message):
        load_sensor_map(path)


def test_optional_preset_entries_may_be_absent_required_may_not(tmp_path):
    rec = make_recording(names=("TT", "TD", "TL", "TR", "JAW"), audio_rate=None)  # no head reference
    write_recording(rec, tmp_path / "a.tsv")
    mapped = read_recording(tmp_path / "a.tsv", sensor_map="paper")
    assert sorted(mapped.sensor_names) == ["JAW", "TD", "TL", "TR", "TT"]
    np.testing.assert_allclose(mapped.sensors["TL"], rec.sensors["TL"], atol=1e-9, equal_nan=True)
    with pytest.raises(RecordingError, match=r"channel 0 for REF1"):
        read_recording(tmp_path / "a.tsv", sensor_map={"REF1": 0, "TT": 1})


def test_map_values_can_be_ids_digit_strings_or_default_names(tmp_path):
    rec = make_recording(names=("S3", "S9"), audio_rate=None)
    write_recording(rec, tmp_path / "b.tsv")
    for value in (3, "3", "S3"):
        mapped = read_recording(tmp_path / "b.tsv", sensor_map={"TT": value})
        assert mapped.sensor_names == ["TT", "S9"]


def test_a_sensor_map_beside_the_file_is_used_unless_one_is_given(tmp_path):
    """Corpus folders carry their channel names in sensor_map.json."""
    import json

    import numpy as np

    from tonguevis.io import Recording, read_recording, write_recording

    rec = Recording(rate=100.0, times=np.arange(5) / 100.0,
                    sensors={"S1": np.zeros((5, 3)), "S2": np.ones((5, 3)) * 0.01})
    path = tmp_path / "take.csv"
    write_recording(rec, path)
    assert sorted(read_recording(path).sensors) == ["S1", "S2"]
    (tmp_path / "sensor_map.json").write_text(json.dumps({"TT": "S1"}))
    assert sorted(read_recording(path).sensors) == ["S2", "TT"]
    assert sorted(read_recording(path, sensor_map={}).sensors) == ["S1", "S2"]


def test_a_map_states_the_files_axes_so_no_command_guesses_them(tmp_path, capsys):
    """Issue 27, item 4: an ``"axes"`` entry of sensor_map.json is the reader's axes=; the demo states its own."""
    from tonguevis.cli import main
    from tonguevis.io.recording import unstated_axes_note
    from tonguevis.paths import DATA_DIR

    demo = read_recording(DATA_DIR / "spk1_ta.tsv")  # its sensor_map.json says "axes": "x,y,z"
    assert demo.metadata["frame"] == "tonguevis" and unstated_axes_note(demo) is None
    assert main(["info", str(DATA_DIR / "spk1_ta.tsv")]) == 0
    assert "axes" not in capsys.readouterr().out

    rec = make_recording(names=("S1", "S2"), audio_rate=None)
    write_recording(rec, tmp_path / "take.tsv")
    device = read_recording(tmp_path / "take.tsv")
    assert device.metadata["frame"] == "device" and "does not state its axes" in unstated_axes_note(device)
    assert unstated_axes_note(device, short=True).startswith("axes not stated")  # the app's status bar
    assert main(["info", str(tmp_path / "take.tsv")]) == 0
    assert capsys.readouterr().out.count("does not state its axes") == 1  # once, on the frame line

    (tmp_path / "sensor_map.json").write_text(json.dumps({"sensors": {"TT": 1}, "axes": "-y,x,z"}))
    stated = read_recording(tmp_path / "take.tsv")
    assert stated.metadata["frame"] == "tonguevis" and unstated_axes_note(stated) is None
    device_tt = device.sensors["S1"]
    np.testing.assert_allclose(stated.sensors["TT"], np.column_stack([-device_tt[:, 1], device_tt[:, 0],
                                                                      device_tt[:, 2]]), atol=1e-12)
    # The reader option given on the command line wins over the map's.
    assert read_recording(tmp_path / "take.tsv", axes="x,y,z").sensors["TT"] == pytest.approx(device_tt)

    (tmp_path / "sensor_map.json").write_text(json.dumps({"sensors": {"TT": 1}, "axes": "up,left,front"}))
    with pytest.raises(RecordingError, match=r"sensor_map.json.*'axes' 'up,left,front' is not an axis mapping"):
        read_recording(tmp_path / "take.tsv")


def test_a_haskins_file_without_a_map_reads_tr_as_the_tongue_rear_and_says_so(caplog):
    """Issue 23: MVIEW's TR (tongue rear) was read as our right lateral sensor, silently."""
    import logging

    from tests.conftest import shared_file

    path = shared_file("ema", "mview", "F01_B01_S01_R01_N.mat")
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        plain = read_recording(path)
    said = [r.getMessage() for r in caplog.records if "channel TR" in r.getMessage()]
    assert len(said) == 1 and "F01_B01_S01_R01_N.mat" in said[0]
    assert "read as the tongue rear (back) (TBK)" in said[0] and "MVIEW (Haskins)" in said[0]
    assert '--sensors MAP with {"TR": "TR"}' in said[0]  # how to choose the other meaning
    assert "TBK" in plain.sensors and "TR" not in plain.sensors
    assert plain.metadata["channel_meanings"] == {"TR": "TBK"}
    preset = read_recording(path, sensor_map="haskins")  # the same as the preset
    np.testing.assert_array_equal(plain.sensors["TBK"], preset.sensors["TBK"])
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        kept = read_recording(path, sensor_map={"TR": "TR"})  # a map decides: no guess, no warning
    assert "TR" in kept.sensors and not [r for r in caplog.records if "channel TR" in r.getMessage()]


def test_tr_without_tl_elsewhere_stays_the_right_lateral_with_a_warning(tmp_path, caplog):
    import logging

    rec = make_recording(names=("TT", "TB", "TR", "JAW"), audio_rate=None, orientation=False)
    path = tmp_path / "three.csv"
    write_recording(rec, path)
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        read = read_recording(path)
    said = [r.getMessage() for r in caplog.records if "channel TR" in r.getMessage()]
    assert len(said) == 1 and "three.csv" in said[0]
    assert "read as the right lateral tongue sensor (TR)" in said[0] and "haskins" in said[0]
    assert "TR" in read.sensors and read.metadata["channel_meanings"] == {"TR": "TR"}


def test_tr_beside_tl_is_the_lateral_pair_without_a_warning(tmp_path, caplog):
    import logging

    from tonguevis.io.sensor_map import resolve_two_meanings

    rec = make_recording(names=("TT", "TD", "TL", "TR"), audio_rate=None, orientation=False)
    rec.metadata["format"] = "mview"  # even in an MVIEW file: TL beside TR means the laterals
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        same = resolve_two_meanings(rec)
    assert same is rec and not caplog.records
