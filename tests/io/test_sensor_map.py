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
