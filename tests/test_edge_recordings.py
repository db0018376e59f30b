"""Generated recordings with the quirks of real EMA, through ``tonguevis simulate`` and ``syllables``.

Cut from the demo /ta/ (tests/edge_recordings.py): speech from the first frame,
under 3 s, a tongue sensor lost for 0.1 s, 1 s and half the recording (NaN
stretches; in an NDI Wave TSV, status 119 with empty fields), a lateral sensor
missing throughout, 250 Hz, irregular timestamps with and without dropped
frames.  Each gives a result with plausible figures (volume change < 2 %,
far-field amplification < 3) or one clear error line, never a traceback.
"""

from __future__ import annotations

import logging
import re

import numpy as np
import pytest

from tests import edge_recordings as edge
from tonguevis.cli import main

PLAUSIBILITY = re.compile(r"far-field amplification (\d+\.\d+) .*max volume change (\d+\.\d+) %")


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def check_plausible(out: str) -> None:
    found = PLAUSIBILITY.search(out)
    assert found, out
    amplification, volume = float(found.group(1)), float(found.group(2))
    assert amplification < 3.0 and volume < 2.0, out


@pytest.fixture(scope="module")
def base():
    """7 s of the demo /ta/: 1.9 s of rest, then two trains of five /ta/ (2.1-6.1 s)."""
    return edge.demo(3.0, 10.0)


CASES = {  # name -> (make(base) -> recording, file suffix)
    "speech-from-the-first-frame": (lambda b: edge.demo(5.2, 9.2), ".csv"),
    "under-3-s": (lambda b: edge.demo(5.2, 7.7), ".csv"),
    "TD-lost-0.1-s": (lambda b: edge.with_dropout(b, "TD", 3.0, 0.1), ".csv"),
    "TD-lost-1-s": (lambda b: edge.with_dropout(b, "TD", 2.5, 1.0), ".csv"),
    "TD-lost-1-s-ndi-status": (lambda b: edge.with_dropout(b, "TD", 2.5, 1.0), ".tsv"),
    "TD-lost-half-the-recording": (lambda b: edge.with_dropout(b, "TD", 3.5, 10.0), ".csv"),
    "TL-missing-throughout": (lambda b: edge.without(b, "TL"), ".csv"),
    "TL-missing-throughout-ndi-status": (lambda b: edge.without(b, "TL"), ".tsv"),
    "250-Hz": (lambda b: edge.resampled(b, 250.0), ".csv"),
    "irregular-clock": (lambda b: edge.jittered(b, 0.003), ".csv"),
    "irregular-clock-dropped-frames": (lambda b: edge.jittered(b, 0.003, drop_every=7), ".csv"),
    "irregular-clock-dropped-frames-ndi": (lambda b: edge.jittered(b, 0.003, drop_every=7), ".tsv"),
}


@pytest.fixture
def written(base, tmp_path):
    def make(name):
        build, suffix = CASES[name]
        return edge.write(build(base), tmp_path / f"{name}{suffix}")

    return make


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_simulate_gives_plausible_figures(name, written, capsys, caplog):
    path = written(name)
    code, out, err = run(capsys, "simulate", path, "--quiet")
    assert code == 0, err
    check_plausible(out)
    assert "unconverged frames: 0" in out
    if name.startswith("TL-missing"):
        assert "driving sensors: TT->node" in out and "TL->node" not in out, out
        assert "TL has no valid sample in the whole recording and is left out" in caplog.text
    else:
        assert "TL->node" in out
    if name.startswith("TD-lost-0.1"):
        assert "frames flagged" not in out  # bridged by interpolation, nothing released


@pytest.mark.parametrize("name", list(CASES))
def test_syllables_find_the_trains(name, written, capsys):
    code, out, err = run(capsys, "syllables", written(name), "--all")
    assert code == 0, err
    trains = int(re.search(r"trains: (\d+)", out).group(1))
    assert trains == (1 if name == "under-3-s" else 2), out


def test_a_bad_status_stretch_of_an_ndi_export_reads_as_missing(base, tmp_path):
    from tonguevis.io import read_recording

    path = edge.write(edge.with_dropout(base, "TD", 2.5, 1.0), tmp_path / "lost.tsv")
    rec = read_recording(path)  # sensor_map.json beside it names the Ids
    status = rec.metadata["ndi_status"][:, rec.metadata["ndi_ids"].index(2)]  # TD is Id 2 in this file
    assert np.sum(status == 119) == 100 and not rec.valid("TD")[250:350].any() and rec.valid("TD")[:250].all()
    header, first_lost = path.read_text().splitlines()[0], path.read_text().splitlines()[251]
    assert "Sensor 3 Status" in header and "\t2.000000\t119.000000\t\t\t\t" in first_lost  # Id 2: empty fields


@pytest.mark.parametrize("suffix", [".csv", ".tsv"])
def test_irregular_clocks_keep_their_times_and_list_the_gaps(base, tmp_path, suffix):
    """CSV and NDI readers keep jittered times as they are (the simulation steps through them as if uniform)
    and take the rate from the median step; dropped frames are listed, and ``on_uniform_grid`` puts them back
    as NaN frames.  Jitter of ±0.1 ms, as the real NDI Example3 (steps of 9.9-10.1 ms)."""
    from tonguevis.io import read_recording

    jittered = edge.jittered(base, 0.0001, drop_every=7)
    rec = read_recording(edge.write(jittered, tmp_path / f"irregular{suffix}"))
    assert rec.rate == pytest.approx(100.0, rel=1e-3)  # the plain median step read 99.8 Hz
    np.testing.assert_allclose(rec.times, jittered.times, atol=1e-6)
    lost = np.arange(7, base.n_samples - 1, 7)
    assert [round(t, 2) for t, _ in rec.metadata["dropped_frames"]] == [round(t, 2) for t in base.times[lost - 1]]
    assert all(n == 1 for _, n in rec.metadata["dropped_frames"])
    grid = rec.on_uniform_grid()
    assert grid.n_samples == base.n_samples
    assert np.array_equal(np.flatnonzero(~grid.valid("TT")), lost)
    # ±1 ms of jitter alone is no gap
    plain = read_recording(edge.write(edge.jittered(base, 0.001), tmp_path / f"jitter{suffix}"))
    assert plain.metadata["dropped_frames"] == [] and plain.rate == pytest.approx(100.0, rel=0.01)


def test_the_rate_of_a_jittered_clock_with_many_dropped_frames():
    from tonguevis.io._common import estimate_rate

    rng = np.random.default_rng(1)
    nominal = np.arange(3000) / 100.0
    times = np.delete(nominal, np.arange(2, 3000, 3)) + rng.uniform(-0.001, 0.001, 2000)  # every 3rd frame lost
    assert estimate_rate(times) == pytest.approx(100.0, rel=0.005)  # the plain median step read 98 Hz
    assert estimate_rate(nominal) == 100.0 and estimate_rate(nominal[::2]) == 50.0


def test_250_hz_is_read_at_its_rate(base, tmp_path, capsys):
    path = edge.write(edge.resampled(base, 250.0), tmp_path / "fast.csv")
    code, out, err = run(capsys, "info", path)
    assert code == 0 and "sample rate:    250.000 Hz" in out and "dropped frames: none" in out, (out, err)


@pytest.mark.slow
def test_a_dropout_does_not_change_the_figures_much(base, tmp_path):
    """1 s of TD lost mid-speech: volume change and peak energy close to the run without (rest given)."""
    from tonguevis.sim import TongueModel
    from tonguevis.workflows import simulate_recording

    model = TongueModel.default()
    full = simulate_recording(base, model)
    rest = tuple(full.metadata["rest"]["interval"])
    lost = simulate_recording(edge.with_dropout(base, "TD", 2.5, 1.0), model, rest=rest)
    assert lost.metadata["dropouts"]["released_frames"] == 100
    assert np.abs(lost.volume_change).max() <= 1.5 * np.abs(full.volume_change).max()
    assert lost.energy.max() <= 1.5 * full.energy.max()


@pytest.mark.slow
def test_releasing_a_handed_over_sensor_flags_no_frame(base):
    from tonguevis.sim import TongueModel
    from tonguevis.workflows import simulate_recording

    motion = simulate_recording(edge.with_dropout(base, "TD", 2.5, 1.0), TongueModel.default())
    assert motion.metadata["recovered_frames"] == [] and motion.metadata["implausible_frames"] == []


def test_too_short_to_find_a_rest_says_how_to_give_one(tmp_path, capsys):
    path = edge.write(edge.demo(5.2, 5.3), tmp_path / "tiny.csv")
    code, out, err = run(capsys, "simulate", path, "--quiet")
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "(11 samples, 0.11 s)" in lines[0] and "--rest START END" in lines[0], err
    code, out, err = run(capsys, "simulate", path, "--quiet", "--rest", "0", "0.03")
    assert code == 0 and "rest: 0.00-0.03 s (given)" in out, err


def test_unnamed_channels_say_how_to_give_a_sensor_map(base, tmp_path, capsys, caplog):
    renamed = base.renamed({n: f"CH{k + 1}" for k, n in enumerate(base.sensor_names)})
    renamed = renamed.with_sensors({**renamed.sensors, "CH1": np.full_like(renamed.sensors["CH1"], np.nan)})
    path = edge.write(renamed, tmp_path / "channels.csv")
    code, out, err = run(capsys, "simulate", path, "--quiet")
    assert code == 2
    line = err.strip()
    assert "\n" not in line and "--sensors MAP" in line and "sensor_map.json beside the file" in line, err
    assert '{"TT": "CH2", "TB": "CH3", "TD": "CH4"}' in line, line  # the example skips the empty CH1
    # ... and following it works
    (tmp_path / "map.json").write_text('{"TT": "CH2", "TD": "CH3", "TL": "CH4", "TR": "CH5", "JAW": "CH6"}')
    with caplog.at_level(logging.WARNING):
        code, out, err = run(capsys, "simulate", path, "--sensors", tmp_path / "map.json", "--quiet")
    assert code == 0, err
    check_plausible(out)


@pytest.mark.slow
def test_validate_leaves_out_a_sensor_that_never_worked(written, tmp_path, capsys, caplog):
    import json

    code, out, err = run(capsys, "validate", written("TL-missing-throughout"), "--json", tmp_path / "v.json",
                         "--no-static", "--quiet")
    assert code == 0, err
    check_plausible(out)
    assert list(json.loads((tmp_path / "v.json").read_text())["sensors"]) == ["TT", "TD", "TR"]
    assert caplog.text.count("TL has no valid sample in the whole recording") == 1
