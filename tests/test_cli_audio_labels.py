"""The command line's --audio, --labels, --textgrid and --productions-from (audio pairing and Praat labels)."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.io.examples import make_ag501
from tests.io.synthetic import make_recording
from tonguevis.cli import build_parser, main
from tonguevis.io import Audio, Label, write_recording
from tonguevis.io.textgrid import write_textgrid
from tonguevis.io.wav import write_wav
from tonguevis.paths import DATA_DIR

DEMO = DATA_DIR / "spk1_ta.tsv"
#: command -> arguments before the options (files named as a user would).
READERS = {
    "info": ["r.pos"], "syllables": ["r.pos"], "convert": ["r.pos", "o.csv"], "simulate": ["r.pos"],
    "export-video": ["r.pos", "--out", "v.mp4"], "energy": ["r.pos", "--csv", "e.csv"],
    "segment": ["r.pos", "--out", "s.vtu"], "validate": ["r.pos", "--json", "v.json"], "view": ["r.pos"],
}
#: Commands that also read a recording's TextGrid from --labels (energy's --labels is its name table;
#: export-video's video has the sound only).
LABELLED = ("info", "syllables", "convert", "simulate", "segment", "validate", "view")
#: Commands that use productions.
PRODUCTIONS = ("syllables", "energy", "segment")


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def tone(seconds: float, rate: float = 8000.0) -> Audio:
    t = np.arange(int(round(seconds * rate))) / rate
    return Audio(samples=0.3 * np.sin(2 * np.pi * 180.0 * t), rate=rate)


def ag501(folder: Path, seconds: float) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    return make_ag501(folder, n_frames=int(round(250 * seconds))).path


@pytest.mark.parametrize("command", sorted(READERS))
def test_every_command_that_reads_a_recording_takes_audio(command):
    args = build_parser().parse_args([command, *READERS[command], "--audio", "take.wav"])
    assert args.audio == Path("take.wav")
    if command in LABELLED:
        args = build_parser().parse_args([command, *READERS[command], "--labels", "take.TextGrid"])
        assert args.label_file == Path("take.TextGrid")
    if command in PRODUCTIONS:
        args = build_parser().parse_args([command, *READERS[command], "--productions-from", "syll"])
        assert args.productions_from == "syll"


def test_info_with_an_explicit_sound_file_and_a_missing_one(tmp_path, capsys):
    pos = ag501(tmp_path, 1.0)
    wav = tmp_path / "sound" / "other_name.wav"
    wav.parent.mkdir()
    write_wav(tone(1.0), wav)
    code, out, _ = run(capsys, "info", pos)
    assert code == 0 and "audio:          none" in out
    code, out, _ = run(capsys, "info", pos, "--audio", wav)
    assert code == 0 and f"audio:          8000 Hz, 1.000 s ({wav})" in out
    code, _, err = run(capsys, "info", pos, "--audio", tmp_path / "missing.wav")
    assert code == 2 and "missing.wav" in err and "does not exist" in err


def test_info_pairs_the_carstens_wav_folder(tmp_path, capsys):
    pos = ag501(tmp_path / "session" / "pos", 1.0)
    (tmp_path / "session" / "wav").mkdir()
    write_wav(tone(1.0), tmp_path / "session" / "wav" / f"{pos.stem}.wav")
    code, out, _ = run(capsys, "info", pos)
    assert code == 0 and f"({tmp_path / 'session' / 'wav' / pos.stem}.wav)" in out


def test_cli_shows_the_length_mismatch_warning_with_both_durations(tmp_path):
    pos = ag501(tmp_path, 2.0)
    write_wav(tone(3.0), pos.with_suffix(".wav"))
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    done = subprocess.run([sys.executable, "-m", "tonguevis", "info", str(pos)], capture_output=True, text=True,
                          env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "WARNING" in done.stderr and "3.000 s" in done.stderr and "2.000 s" in done.stderr


def test_info_lists_the_tiers_of_the_textgrid_beside_it(tmp_path, capsys):
    pos = ag501(tmp_path, 2.0)
    write_textgrid([Label(0.1, 0.5, "ta", "syll"), Label(0.5, 0.9, "ta", "syll"), Label(0.3, 0.3, "x", "pts")],
                   pos.with_suffix(".TextGrid"), end=2.0)
    code, out, _ = run(capsys, "info", pos)
    assert code == 0 and "labels:         2 syll, 1 pts: ta ta" in out
    assert f"label file:     {pos.with_suffix('.TextGrid')}" in out
    code, out, _ = run(capsys, "info", pos, "-O", "labels=false")
    assert "labels:         none" in out


# ------------------------------------------------------------------ --textgrid
def test_syllables_textgrid_holds_the_productions_for_praat(tmp_path, capsys):
    from praatio import textgrid

    from tonguevis.workflows import find_recording_productions, open_recording

    if not DEMO.exists():
        pytest.skip(f"demo corpus not built: {DEMO}")
    out = tmp_path / "ta.TextGrid"
    code, printed, err = run(capsys, "syllables", DEMO, "--textgrid", out)
    assert code == 0, err
    landmark_tiers = ("GONS", "PVEL", "NONS", "MAXC", "NOFFS", "PVEL2", "GOFFS", "VTARG")
    assert f"wrote {out} (tiers: productions, events, {', '.join(landmark_tiers)})" in printed
    rec = open_recording(DEMO)
    table = find_recording_productions(rec)
    grid = textgrid.openTextgrid(str(out), includeEmptyIntervals=False)
    assert grid.tierNames == ("productions", "events") + landmark_tiers
    intervals = grid.getTier("productions").entries
    assert [e.label for e in intervals] == ["ta"] * len(table)  # the syllable, from the file name
    np.testing.assert_allclose([(e.start, e.end) for e in intervals], [(p.start, p.end) for p in table], atol=1e-9)
    points = grid.getTier("events").entries
    expected = sorted([(p.release, "release") for p in table] + [(p.vowel, "vowel") for p in table])
    assert [e.label for e in points] == [what for _, what in expected]
    np.testing.assert_allclose([e.time for e in points], [t for t, _ in expected], atol=1e-6)
    # one point per production in each landmark tier, named by its production, in lp_findgest's order
    keys = ("gons", "pvel", "nons", "maxc", "noffs", "pvel2", "goffs", "vowel")
    for key, name in zip(keys, landmark_tiers):
        marks = grid.getTier(name).entries
        assert [e.label for e in marks] == [f"{p.train}.{p.index}" for p in table]
        np.testing.assert_allclose([e.time for e in marks], [m.times[key] for m in table.landmarks], atol=1e-6)
    for m, p in zip(table.landmarks, table):
        t = m.times
        assert t["gons"] < t["pvel"] < t["nons"] <= t["maxc"] <= t["noffs"] < t["pvel2"] < t["goffs"]
        assert t["maxc"] == p.closure and t["maxc"] < p.release < t["vowel"] == p.vowel
    # it spans the sound, from 0 s, so it lines up with the WAV in Praat
    assert grid.minTimestamp == 0.0 and grid.maxTimestamp == pytest.approx(rec.audio.duration, abs=0.02)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ta.TextGrid"]  # atomic: no temporary left


def test_syllables_textgrid_keeps_the_recordings_own_tiers(tmp_path, capsys):
    from tonguevis.io.textgrid import read_textgrid

    rec_path = tmp_path / "take.csv"
    write_recording(_train_recording(), rec_path)
    write_textgrid([Label(0.5, 1.5, "hello", "words")], rec_path.with_suffix(".TextGrid"), end=4.0)
    out = tmp_path / "out.TextGrid"
    code, printed, err = run(capsys, "syllables", rec_path, "--all", "--textgrid", out)
    assert code == 0, err
    labels = read_textgrid(out)
    assert Label(0.5, 1.5, "hello", "words") in labels
    assert {lab.tier for lab in labels} == {"words", "productions", "events", "GONS", "PVEL", "NONS", "MAXC",
                                            "NOFFS", "PVEL2", "GOFFS", "VTARG"}


# ------------------------------------------------------------------ --productions-from
SYLL = [Label(0.6, 1.0, "ta", "syll"), Label(1.0, 1.4, "ta", "syll"), Label(2.2, 2.6, "ka", "syll")]


def _train_recording():
    """4 s of a tongue tip TT rising and falling twice a second, no audio."""
    rec = make_recording(n=400, names=("TT",), audio_rate=None, with_gaps=False, orientation=False)
    t = rec.times - rec.times[0]
    tip = np.column_stack([np.zeros_like(t), np.zeros_like(t), 0.005 * np.cos(2 * np.pi * 2 * t)])
    return rec.with_sensors({"TT": tip}, times=t)


def test_syllables_productions_from_a_tier_beside_the_recording(tmp_path, capsys):
    rec_path = tmp_path / "take.csv"
    write_recording(_train_recording(), rec_path)
    write_textgrid(SYLL, rec_path.with_suffix(".TextGrid"), end=4.0)
    table = tmp_path / "p.csv"
    code, out, err = run(capsys, "syllables", rec_path, "--productions-from", "syll",
                         "--csv", table)
    assert code == 0, err
    assert "from the label tier 'syll'" in out
    with open(table, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [(int(r["train"]), int(r["index"]), float(r["start_s"]), float(r["end_s"])) for r in rows] == [
        (1, 1, 0.6, 1.0), (1, 2, 1.0, 1.4), (2, 1, 2.2, 2.6)]
    assert [r["label"] for r in rows] == ["ta", "ta", "ka"]  # the labels carried into the table
    # vowels: the tip's lowest point inside each interval (cos(4πt) is lowest at 0.75, 1.25, 2.25 s)
    assert [float(r["vowel_s"]) for r in rows] == pytest.approx([0.75, 1.25, 2.25], abs=0.011)


def test_productions_from_an_explicit_textgrid_and_a_missing_tier(tmp_path, capsys):
    rec_path = tmp_path / "take.csv"
    write_recording(_train_recording(), rec_path)
    grid = tmp_path / "elsewhere" / "annotation.TextGrid"
    grid.parent.mkdir()
    write_textgrid(SYLL + [Label(1.0, 1.0, "click", "events")], grid, end=4.0)
    code, out, err = run(capsys, "syllables", rec_path, "--labels", grid,
                         "--productions-from", "syll")
    assert code == 0, err
    assert "productions shown: every labelled interval (3)" in out
    code, _, err = run(capsys, "syllables", rec_path, "--labels", grid,
                       "--productions-from", "syllables")
    assert code == 2
    assert "no label tier 'syllables'" in err and "tiers: syll, events" in err
    code, _, err = run(capsys, "syllables", rec_path, "--productions-from", "syll")
    assert code == 2 and "--labels FILE" in err


def test_malformed_textgrid_is_a_one_line_error_naming_it(tmp_path, capsys):
    rec_path = tmp_path / "take.csv"
    write_recording(_train_recording(), rec_path)
    rec_path.with_suffix(".TextGrid").write_text("this is not a TextGrid\n")
    code, _, err = run(capsys, "syllables", rec_path)
    assert code == 2 and "take.TextGrid" in err and "TextGrid" in err and "Traceback" not in err


def _demo_with_textgrid(folder: Path, labels) -> Path:
    """The demo /ta/ (linked, with its WAV and sensor map) and a TextGrid beside it."""
    if not DEMO.exists():
        pytest.skip(f"demo corpus not built: {DEMO}")
    for name in (DEMO.name, DEMO.with_suffix(".wav").name, "sensor_map.json"):
        (folder / name).symlink_to(DATA_DIR / name)
    write_textgrid(labels, folder / DEMO.with_suffix(".TextGrid").name, end=17.0)
    return folder / DEMO.name


def test_energy_curves_of_tier_productions(tmp_path, capsys, monkeypatch):
    from tests.analysis.energy_support import MODES, box_tongue
    from tonguevis.cli import energy as energy_cli

    monkeypatch.setattr(energy_cli, "load_model", lambda args: box_tongue())
    recording = _demo_with_textgrid(tmp_path, [Label(5.45, 5.72, "ta", "syll"), Label(5.72, 5.99, "ta", "syll"),
                                               Label(8.03, 8.30, "ta", "syll")])
    out = tmp_path / "e.csv"
    code, printed, err = run(capsys, "energy", recording, "--csv", out, "--productions-from", "syll",
                             "--modes", MODES, "--landmarks", "rule", "--quiet")
    assert code == 0, err
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert sorted({r["production"] for r in rows}) == ["1.1", "1.2", "2.1"]
    first = [float(r["recording_time_s"]) for r in rows if r["production"] == "1.1"]
    assert min(first) == pytest.approx(5.45, abs=0.011) and max(first) == pytest.approx(5.72, abs=0.011)
    code, _, err = run(capsys, "energy", recording, "--csv", out, "--productions-from", "words", "--quiet")
    assert code == 2 and "no label tier 'words'" in err and "tiers: syll" in err


def test_energy_audio_names_one_recording(tmp_path, capsys):
    if not DEMO.exists():
        pytest.skip(f"demo corpus not built: {DEMO}")
    code, _, err = run(capsys, "energy", DATA_DIR, "--csv", tmp_path / "e.csv", "--audio", DEMO.with_suffix(".wav"))
    assert code == 2 and "--audio names the sound of one recording" in err and "NAME.wav" in err


def test_segment_counts_productions_in_the_tier(tmp_path, capsys, monkeypatch):
    from tests.analysis.segmentation_support import box_model
    from tonguevis.cli import segment as segment_cli

    model = box_model()
    monkeypatch.setattr(segment_cli, "load_model", lambda mesh, axes: model)
    recording = _demo_with_textgrid(tmp_path, [Label(5.45, 5.72, "ta", "syll"), Label(8.03, 8.30, "ta", "syll")])
    common = ["segment", recording, "--modes", "20", "--landmarks", "rule", "--quiet", "--mode-kind", "rigid",
              "--seeds", "2", "--out", tmp_path / "s.vtu"]
    code, out, err = run(capsys, *common, "--production", "2", "--productions-from", "syll")
    assert code == 0, err
    assert "target: production 8.03" in out  # the tier's second interval, not the automatic 2nd production
    code, _, err = run(capsys, *common, "--production", "3", "--productions-from", "syll")
    assert code == 2 and "the recording has 2" in err and "--productions-from syll" in err
    code, _, err = run(capsys, *common, "--productions-from", "syll")
    assert code == 2 and "give --production K too" in err


def test_energy_reads_its_one_recording_with_the_given_sound(tmp_path, capsys, monkeypatch):
    import tonguevis.workflows.recording as workflows  # where the corpus opens each recording
    from tonguevis.errors import RecordingError

    if not DEMO.exists():
        pytest.skip(f"demo corpus not built: {DEMO}")
    seen = {}

    def open_recording(path, sensor_map=None, **options):
        seen.update(options)
        raise RecordingError("stop here", path)

    monkeypatch.setattr(workflows, "open_recording", open_recording)
    wav = tmp_path / "other.wav"
    code, _, err = run(capsys, "energy", DEMO, "--csv", tmp_path / "e.csv", "--audio", wav, "--quiet")
    assert code == 2 and "stop here" in err
    assert seen == {"audio": wav}


def test_info_says_the_sound_is_the_files_own(tmp_path, capsys):
    from tests.io.examples import make_mview_v5

    example = make_mview_v5(tmp_path)
    code, out, _ = run(capsys, "info", example.path)
    assert code == 0 and "audio:          8000 Hz, 0.200 s (in the file)" in out


def test_textgrid_without_productions_still_has_both_tiers(tmp_path):
    from praatio import textgrid

    from tonguevis.preprocess.labelled import write_productions_textgrid
    from tonguevis.preprocess.productions import ProductionTable

    out = tmp_path / "none.TextGrid"
    assert write_productions_textgrid(out, ProductionTable(), _train_recording()) == [
        "productions", "events", "GONS", "PVEL", "NONS", "MAXC", "NOFFS", "PVEL2", "GOFFS", "VTARG"]
    grid = textgrid.openTextgrid(str(out), includeEmptyIntervals=False)
    assert type(grid.getTier("events")).__name__ == "PointTier"
    assert type(grid.getTier("productions")).__name__ == "IntervalTier"
    assert grid.maxTimestamp == pytest.approx(4.0)
