"""Every CLI command on every real recording in ../shared/data/ema that has tongue sensors.

The Opti-Speech exports (the /ka/ 006 and 007, the /ta/ 009 and the palate
traces 002-004, whose five tongue sensors recorded too) need no sensor map;
the Haskins sentence takes ``--sensors haskins``.  One simulation per file
(``tonguevis simulate``, its motion kept as motion.npz: ``--out`` for the
Haskins file, whose VTK series is small; a spy on the workflow for the longer
ones) feeds ``segment`` and ``morph``, which accept a saved motion.  ``energy``
and ``validate`` simulate on their own: they run here on the recordings that
tests/test_cli_rest.py does not already take through them (002, 003, 004, 007).
The NDI Wave Example3 has no sensor map (every simulating command says how to
give one, in one line); rticulate_0025.pos is 0.1 s long (too short to find a
rest: one line saying how to give it; with ``--rest`` a result).
Skips when ../shared is absent.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

from tests.conftest import shared_file
from tonguevis.cli import main

OPTISPEECH = {
    "002-palate-midsagittal": "002_OSN12_Palate_MidSagital_HR.tsv",
    "003-palate-coronal": "003_OSN12_Palate_Coronal_HR.tsv",
    "004-palate-scribble": "004_OSN12_Palate_Scribble_HR.tsv",
    "006-ka": "006_OSN12_Kah_nofb_natural_take2_HR.tsv",
    "007-ka-feedback": "007_OSN12_Kah_withFb_natural_HR.tsv",
    "009-ta-feedback": "009_OSN12_Tah_withFb_natural_HR.tsv",
}
REAL = {name: (("ema", "optispeech", file), []) for name, file in OPTISPEECH.items()}
REAL["haskins"] = (("ema", "mview", "F01_B01_S01_R01_N.mat"), ["--sensors", "haskins"])
DRIVING = {name: ["TT", "TB", "TD", "TL", "TR"] for name in OPTISPEECH}
DRIVING["haskins"] = ["TT", "TB", "TBK"]
#: energy and validate on the recordings tests/test_cli_rest.py does not take through them
#: The articulator the productions are found on (the syllable in the file name; the tip otherwise).
ARTICULATOR = {"006-ka": "TD", "007-ka-feedback": "TD"}
NOT_YET_COVERED = ["002-palate-midsagittal", "003-palate-coronal", "004-palate-scribble", "007-ka-feedback"]

PLAUSIBILITY = re.compile(r"far-field amplification (\d+\.\d+) .*max volume change (\d+\.\d+) %")
REST = re.compile(r"rest: \d+\.\d\d-\d+\.\d\d s \((stillest window|detected)[^)]*\)")


def real(name: str) -> tuple[Path, list[str]]:
    parts, options = REAL[name]
    return shared_file(*parts), list(options)


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def plausibility(out: str) -> tuple[float, float]:
    """(amplification, volume change %) from the printed plausibility line."""
    found = PLAUSIBILITY.search(out)
    assert found, out
    return float(found.group(1)), float(found.group(2))


@pytest.mark.parametrize("name", list(REAL))
def test_info_and_convert(name, tmp_path, capsys):
    path, options = real(name)
    code, out, err = run(capsys, "info", path, *options)
    assert code == 0, err
    assert "sample rate:    100.000 Hz" in out
    for sensor in DRIVING[name]:
        assert re.search(rf"^  {sensor}\s+100\.0%", out, re.MULTILINE), (sensor, out)
    csv = tmp_path / "out.csv"
    code, out, err = run(capsys, "convert", path, csv, *options)
    assert code == 0, err
    from tonguevis.io import read_recording

    original, back = read_recording(path, sensor_map=options[1] if options else None), read_recording(csv)
    assert back.n_samples == original.n_samples and set(back.sensors) == set(original.sensors)
    for sensor in DRIVING[name]:
        np.testing.assert_allclose(back.sensors[sensor], original.sensors[sensor], atol=1e-6)  # micrometres


@pytest.mark.parametrize("name", list(REAL))
def test_syllables(name, tmp_path, capsys):
    path, options = real(name)
    code, out, err = run(capsys, "syllables", path, *options, "--all", "--csv", tmp_path / "p.csv")
    assert code == 0, err
    found = re.search(r"trains: (\d+) \(from the (audio envelope|\w+ motion)", out)
    assert found, out
    assert found.group(2) == ("audio envelope" if name == "haskins" else f"{ARTICULATOR.get(name, 'TT')} motion")
    rows = (tmp_path / "p.csv").read_text().strip().splitlines()[1:]
    if "palate" in name:  # a probe drawn along the palate: no CV syllable in it, and it says so
        assert not rows and "note: no CV production found" in out, out
    else:
        assert rows, "no production found"
    if name == "haskins":
        assert "head motion removed" not in out  # MVIEW files are head-corrected already


@pytest.fixture(scope="module")
def simulations(tmp_path_factory):
    """name -> (exit code, stdout, motion.npz): ``tonguevis simulate`` run once per recording."""
    cache: dict[str, tuple[int, str, Path]] = {}

    def simulated(name: str):
        if name not in cache:
            path, options = real(name)
            folder = tmp_path_factory.mktemp(name)
            kept = {}
            import importlib

            workflows = importlib.import_module("tonguevis.sim.simulate")  # the module, not the function
            original = workflows.simulate

            def spy(*args, **kwargs):
                kept["motion"] = original(*args, **kwargs)
                return kept["motion"]

            argv = ["simulate", str(path), *options, "--quiet"]
            if name == "haskins":  # 262 frames: the VTK series is small enough to write
                argv += ["--out", str(folder)]
            out = io.StringIO()
            with contextlib.redirect_stdout(out), mock.patch.object(workflows, "simulate", spy):
                code = main(argv)
            saved = folder / "motion.npz"
            if name != "haskins":
                kept["motion"].save(saved)
            cache[name] = (code, out.getvalue(), saved)
        return cache[name]

    return simulated


@pytest.mark.slow
@pytest.mark.parametrize("name", list(REAL))
def test_simulate(name, simulations):
    code, out, saved = simulations(name)
    assert code == 0, out
    assert len(REST.findall(out)) == 1, out
    assert "driving sensors: " + ", ".join(f"{s}->node" for s in DRIVING[name]) in re.sub(r" \d+", "", out), out
    amplification, volume = plausibility(out)
    assert amplification < 3.0 and volume < 2.0, out
    assert "frames flagged" not in out and "unconverged frames: 0" in out, out
    from tonguevis.sim import Motion

    motion = Motion.load(saved)
    p = motion.metadata["plausibility"]
    assert p["volume_change_max_percent"] == pytest.approx(volume, abs=0.01)
    assert np.isfinite(motion.q).all() and motion.n_frames > 200


@pytest.mark.slow
@pytest.mark.parametrize("name", list(REAL))
def test_segment_and_morph_take_the_saved_motion(name, simulations, tmp_path, capsys):
    _, simulated, saved = simulations(name)
    rest = REST.search(simulated).group(0)
    code, out, err = run(capsys, "segment", saved, "--out", tmp_path / "s.vtu", "--mode-kind", "rigid", "--seeds", "2",
                         "--quiet")
    assert code == 0, err
    assert rest in out and "2 partitions" in out and (tmp_path / "s.vtu").stat().st_size > 0
    code, out, err = run(capsys, "morph", f"{saved}@0.5", f"{saved}@1.5", "--out", tmp_path / "m.png", "--quiet")
    assert code == 0, err
    assert rest in out and (tmp_path / "m.png").stat().st_size > 0
    gap = float(re.search(r"node distance source-target: max (\d+\.\d+) mm", out).group(1))
    assert 0.0 < gap < 30.0, out  # two shapes of one tongue 1 s apart: millimetres, not metres


@pytest.mark.slow
@pytest.mark.parametrize("name", NOT_YET_COVERED)
def test_energy(name, tmp_path, capsys):
    path, options = real(name)
    code, out, err = run(capsys, "energy", path, *options, "--csv", tmp_path / "e.csv", "--all", "--quiet")
    assert code == 0, err
    assert REST.search(out), out
    curves = int(re.search(r"1 recording\(s\), (\d+) production curves", out).group(1))
    if "palate" in name:  # a palate trace has no CV production
        assert curves == 0, out
        return
    assert curves > 0, out
    peaks = [float(v) for v in re.findall(r"peak (\d+\.\d+) ±", out)]
    assert peaks and all(0 < v < 50 for v in peaks), out  # millijoules, as the demo's


@pytest.mark.slow
@pytest.mark.parametrize("name", NOT_YET_COVERED)
def test_validate(name, tmp_path, capsys):
    path, options = real(name)
    code, out, err = run(capsys, "validate", path, *options, "--json", tmp_path / "v.json", "--no-static", "--quiet")
    assert code == 0, err
    amplification, volume = plausibility(out)
    assert amplification < 3.0 and volume < 2.0, out
    doc = json.loads((tmp_path / "v.json").read_text())
    assert set(doc["sensors"]) == set(DRIVING[name])
    assert all(np.isfinite(s["model_rmse_mm"]) and s["model_rmse_mm"] < 10 for s in doc["sensors"].values()), doc


# --- the NDI Wave Example3: no sensor map ---------------------------------------------------------

SIMULATING = {
    "simulate": lambda f, out: ["simulate", f, "--quiet"],
    "energy": lambda f, out: ["energy", f, "--csv", out / "e.csv", "--quiet"],
    "segment": lambda f, out: ["segment", f, "--out", out / "s.vtu", "--quiet"],
    "morph": lambda f, out: ["morph", f"{f}@0.05", f"{f}@0.08", "--out", out / "m.png", "--quiet"],
    "validate": lambda f, out: ["validate", f, "--json", out / "v.json", "--quiet"],
}


def test_ndi_example_reads_and_converts_without_a_map(tmp_path, capsys):
    path = shared_file("ema", "ndi_wave", "Example3.tsv")
    code, out, err = run(capsys, "info", path)
    assert code == 0, err
    assert "sensors (15)" in out and "1 frame(s) missing in 1 gap(s)" in out and "frame:          device" in out
    code, out, err = run(capsys, "convert", path, tmp_path / "x.csv")
    assert code == 0 and "15 sensors, 100 samples" in out, err


@pytest.mark.parametrize("command", ["syllables", *SIMULATING])
def test_ndi_example_without_a_map_says_how_to_give_one(command, tmp_path, capsys):
    path = shared_file("ema", "ndi_wave", "Example3.tsv")
    argv = ["syllables", path] if command == "syllables" else SIMULATING[command](str(path), tmp_path)
    code, out, err = run(capsys, *argv)
    assert code == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"tonguevis {command}: error: {path}"), err
    assert "--sensors MAP" in lines[0], lines[0]
    if command != "syllables":
        # The example names channels that hold data (S2..S7 are empty in this export).
        assert "sensor_map.json" in lines[0] and '"TT": "S0"' in lines[0] and '"S2"' not in lines[0], lines[0]
    assert not list(tmp_path.iterdir())  # nothing written


# --- rticulate_0025.pos: 0.1 s of a real AG500 --------------------------------------------------


@pytest.fixture
def rticulate(tmp_path):
    """The file and a sensor map from its _sensors.csv (3 tongue back, 4 mid, 5 tip, 7 lower jaw)."""
    path = shared_file("ema", "carstens", "rticulate_0025.pos")
    sensor_map = tmp_path / "map.json"
    sensor_map.write_text(json.dumps({"TD": 3, "TB": 4, "TT": 5, "JAW": 7}))
    return path, sensor_map


@pytest.mark.parametrize("command", list(SIMULATING))
def test_rticulate_is_too_short_to_find_a_rest_and_says_how_to_give_one(command, rticulate, tmp_path, capsys):
    path, sensor_map = rticulate
    code, out, err = run(capsys, *SIMULATING[command](str(path), tmp_path), "--sensors", sensor_map)
    assert code == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "0.10 s" in lines[0] and "--rest START END" in lines[0], err


def test_rticulate_with_a_given_rest_simulates(rticulate, capsys):
    path, sensor_map = rticulate
    code, out, err = run(capsys, "simulate", path, "--sensors", sensor_map, "--rest", "0", "0.05", "--quiet")
    assert code == 0, err
    assert "rest: 0.00-0.05 s (given)" in out and "frames: 20 (0.10 s)" in out
    amplification, volume = plausibility(out)
    assert amplification < 3.0 and volume < 2.0, out
