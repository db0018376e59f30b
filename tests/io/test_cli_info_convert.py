"""``tonguevis info`` and ``tonguevis convert``: output, conversions, one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import shared_file
from tests.io.synthetic import make_recording
from tonguevis.cli import main
from tonguevis.io import read_recording, write_recording


@pytest.fixture
def ndi_file(tmp_path):
    rec = make_recording(n=40)
    path = tmp_path / "take.tsv"
    write_recording(rec, path)
    return rec, path


def test_info_reports_format_rate_sensors_audio(ndi_file, capsys):
    rec, path = ndi_file
    assert main(["info", str(path), "--sensors", "paper"]) == 0
    out = capsys.readouterr().out
    assert "format:         ndi_wave" in out
    assert "sample rate:    100.000 Hz" in out
    assert f"samples:        {rec.n_samples}" in out
    td = next(line for line in out.splitlines() if line.strip().startswith("TD "))
    assert f"{100 * (rec.n_samples - 3) / rec.n_samples:5.1f}%" in td  # three frames lost
    assert "audio:          8000 Hz" in out and "take.wav" in out
    assert "dropped frames: none" in out



def test_info_says_orientation_only_where_the_file_has_some(tmp_path, capsys):
    """Issue 37: the demo's Q0..Qz columns are empty, and info said "+orientation" for every sensor."""
    rec = make_recording(n=40)
    names = list(rec.sensors)
    rec.orientations = {name: np.full((rec.n_samples, 4), np.nan) for name in names}
    rec.orientations[names[0]][:, 0] = 1.0  # one sensor with quaternions, the others with empty columns
    path = tmp_path / "take.tsv"
    write_recording(rec, path)
    assert main(["info", str(path)]) == 0
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines() if line.startswith("  ")}
    said = [name for name, line in rows.items() if line.endswith("+orientation")]
    assert len(rows) == len(names) and len(said) == 1  # written as S<Id>: the one with quaternions

def test_info_lists_dropped_frames_and_labels(capsys):
    assert main(["info", str(shared_file("ema", "ndi_wave", "Example3.tsv"))]) == 0
    assert "1 frame(s) missing in 1 gap(s): 1 after 0.999 s" in capsys.readouterr().out
    assert main(["info", str(shared_file("ema", "mview", "F01_B01_S01_R01_N.mat")), "--sensors", "haskins"]) == 0
    out = capsys.readouterr().out
    assert "10 words, 29 phones: sp THE BIRCH CANOE" in out
    assert "\n  TBK " in out


def test_info_reader_options(tmp_path, capsys):
    path = shared_file("ema", "carstens", "artk_ag500.pos")
    assert main(["info", str(path), "-O", "channels=8", "-O", "rate=100"]) == 0
    out = capsys.readouterr().out
    assert "sample rate:    100.000 Hz" in out and "sensors (8)" in out


@pytest.mark.parametrize("suffix", [".bvh", ".csv", ".tsv"])
def test_convert_by_extension_round_trips(ndi_file, tmp_path, suffix, capsys):
    rec, path = ndi_file
    out = tmp_path / f"converted{suffix}"
    assert main(["convert", str(path), str(out), "--sensors", "paper"]) == 0
    assert "wrote" in capsys.readouterr().out
    back = read_recording(out, sensor_map="paper" if suffix == ".tsv" else None)
    assert back.metadata["format"] == {".bvh": "bvh", ".csv": "csv", ".tsv": "ndi_wave"}[suffix]
    for name in rec.sensor_names:
        np.testing.assert_allclose(back.sensors[name], rec.sensors[name], atol=1e-9, equal_nan=True)
    if suffix == ".tsv":
        assert back.audio is not None and back.audio.rate == rec.audio.rate


def test_convert_writer_option(ndi_file, tmp_path):
    _, path = ndi_file
    out = tmp_path / "long.csv"
    assert main(["convert", str(path), str(out), "-W", "layout=long", "-W", "unit=m"]) == 0
    text = out.read_text()
    assert "# unit: m\n" in text and "time,sensor,x,y,z" in text


@pytest.mark.parametrize("argv, message", [
    (["info", "{missing}"], "no such file"),
    (["info", "{junk}"], "unknown recording format"),
    (["info", "{tsv}", "--sensors", "nosuchpreset"], "neither a JSON file nor a preset"),
    (["info", "{tsv}", "--sensors", "haskins"], "no such channel"),
    (["info", "{tsv}", "-O", "nonsense"], "not KEY=VALUE"),
    (["convert", "{tsv}", "{out_xyz}"], "cannot write this format"),
    (["convert", "{tsv}", "{out_csv}", "-W", "bogus=1"], "bad writer option"),
])
def test_errors_are_one_line_with_nonzero_exit(ndi_file, tmp_path, capsys, argv, message):
    _, path = ndi_file
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00garbage\xff" * 10)
    names = {"missing": str(tmp_path / "none.tsv"), "junk": str(junk), "tsv": str(path),
             "out_xyz": str(tmp_path / "o.xyz"), "out_csv": str(tmp_path / "o.csv")}
    code = main([a.format(**names) for a in argv])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
