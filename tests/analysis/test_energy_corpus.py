"""Corpus loading and labels, and energy curves of the demo corpus (library and CLI)."""

from __future__ import annotations

import csv
import json
from types import SimpleNamespace

import numpy as np
import pytest

from tests.analysis.energy_support import MODES, box_tongue
from tonguevis.analysis.corpus import CorpusError, labels_from_name, load_corpus
from tonguevis.workflows.corpus import corpus_energy_curves
from tonguevis.paths import DATA_DIR


@pytest.mark.parametrize("name, speaker, syllable, trial", [
    ("spk1_ta.tsv", "spk1", "ta", 1),
    ("S03-ka-2.pos", "S03", "ka", 2),
    ("spk2_la_t3.tsv", "spk2", "la", 3),
    ("F01 ra take4.ema", "F01", "ra", 4),
])
def test_labels_from_names(tmp_path, name, speaker, syllable, trial):
    entry = labels_from_name(tmp_path / name)
    assert (entry.speaker, entry.syllable, entry.trial) == (speaker, syllable, trial)


def test_labels_from_speaker_folder_and_unknown(tmp_path):
    entry = labels_from_name(tmp_path / "M07" / "ka_2.tsv")
    assert (entry.speaker, entry.syllable, entry.trial, entry.source) == ("M07", "ka", 2, "folder")
    assert labels_from_name(tmp_path / "x" / "recording0001.tsv").speaker == ""


def test_metadata_labels_override_names(tmp_path):
    entry = labels_from_name(tmp_path / "spk1_ta.tsv").apply_metadata({"speaker": "native1", "trial": "3"})
    assert (entry.speaker, entry.syllable, entry.trial, entry.source) == ("native1", "ta", 3, "metadata")


def _touch(path):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("x")
    return path


def test_walk_group_and_table(tmp_path):
    _touch(tmp_path / "spk1_ta.tsv")
    _touch(tmp_path / "spk1_ta.wav")  # audio twin: not a recording
    _touch(tmp_path / "spk2_ta_2.tsv")
    _touch(tmp_path / "spk2" / "ka_1.pos")
    _touch(tmp_path / "notes.txt")
    _touch(tmp_path / "odd" / "take.tsv")
    corpus = load_corpus([tmp_path])
    names = sorted(e.path.name for e in corpus)
    assert names == ["ka_1.pos", "spk1_ta.tsv", "spk2_ta_2.tsv", "take.tsv"]
    groups = corpus.groups(("speaker", "syllable"))
    assert {k: sorted(e.path.name for e in v) for k, v in groups.items()} == {
        ("spk1", "ta"): ["spk1_ta.tsv"], ("spk2", "ta"): ["spk2_ta_2.tsv"], ("spk2", "ka"): ["ka_1.pos"],
        ("odd", "take"): ["take.tsv"],
    }
    assert [e.path.name for e in corpus.select(syllables={"ta"})] == ["spk1_ta.tsv", "spk2_ta_2.tsv"]
    # A user table overrides what the names say; files are matched by stem or relative path.
    table = tmp_path / "labels.csv"
    table.write_text("file,speaker,syllable,trial\nodd/take.tsv,spk3,la,2\nspk1_ta,native,,\n")
    corpus = load_corpus([tmp_path], table=table)
    by_name = {e.path.name: e for e in corpus}
    assert (by_name["take.tsv"].speaker, by_name["take.tsv"].syllable, by_name["take.tsv"].trial) == ("spk3", "la", 2)
    assert (by_name["spk1_ta.tsv"].speaker, by_name["spk1_ta.tsv"].syllable) == ("native", "ta")
    assert by_name["spk1_ta.tsv"].source == "table"


def test_bad_inputs_name_the_file(tmp_path):
    with pytest.raises(CorpusError, match="no such file"):
        load_corpus([tmp_path / "missing"])
    table = tmp_path / "t.csv"
    table.write_text("name,speaker\na,b\n")
    with pytest.raises(CorpusError, match="t.csv.*'file' column|'file' column.*t.csv"):
        load_corpus([tmp_path], table=table)
    table.write_text("file,trial\na,first\n")
    with pytest.raises(CorpusError, match="line 2"):
        load_corpus([tmp_path], table=table)
    with pytest.raises(CorpusError, match="cannot group by"):
        load_corpus([tmp_path]).groups(("colour",))


TRUTH = json.loads((DATA_DIR / "demo_truth.json").read_text())


def _truth_productions(name):
    return [p for p in TRUTH["files"][name]["productions"] if 2 <= p["index"] <= 4]


@pytest.fixture(scope="module")
def demo_result():
    corpus = load_corpus([DATA_DIR / "spk1_ka.tsv", DATA_DIR / "spk2_ka.tsv"])
    return corpus_energy_curves(corpus, model=box_tongue(), modes=MODES, landmarks="rule")


def test_demo_curves_match_the_placed_productions(demo_result):
    for name in ("spk1_ka", "spk2_ka"):
        curves = [c for c in demo_result.curves if c.recording == name]
        truth = _truth_productions(f"{name}.tsv")
        assert len(curves) == len(truth) == 15
        assert [(c.train, c.index) for c in curves] == [(p["train"], p["index"]) for p in truth]
        np.testing.assert_allclose([c.start for c in curves], [p["start"] for p in truth], atol=0.03)
        np.testing.assert_allclose([c.end for c in curves], [p["end"] for p in truth], atol=0.03)
        for c in curves:
            assert c.speaker == name[:4] and c.syllable == "ka"
            motion = demo_result.motions[name]
            np.testing.assert_allclose(c.energy, motion.energy[c.frames])
            np.testing.assert_allclose(c.energy, motion.model.energy(motion.q[c.frames]), rtol=1e-10)
            assert np.all(c.energy >= 0)


def test_cli_energy_writes_long_csv_and_png(tmp_path, monkeypatch):
    from tonguevis.cli import energy as energy_cli
    from tonguevis.cli import main

    monkeypatch.setattr(energy_cli, "load_model", lambda args: box_tongue())
    out, png, summary = tmp_path / "e.csv", tmp_path / "e.png", tmp_path / "s.csv"
    code = main(["energy", str(DATA_DIR / "spk1_ta.tsv"), "--csv", str(out), "--png", str(png),
                 "--summary", str(summary), "--modes", str(MODES), "--landmarks", "rule", "--quiet"])
    assert code == 0
    with open(out, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0][:5] == ["recording", "production", "time_s", "time_norm", "energy_J"]
    body = rows[1:]
    productions = sorted({r[1] for r in body}, key=lambda s: tuple(map(int, s.split("."))))
    truth = _truth_productions("spk1_ta.tsv")
    assert productions == [f"{p['train']}.{p['index']}" for p in truth]
    assert {r[0] for r in body} == {"spk1_ta"}
    norm = np.array([float(r[3]) for r in body])
    assert norm.min() >= 0 and norm.max() <= 1
    assert all(float(r[4]) >= 0 for r in body)
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"
    with open(summary, newline="") as fh:
        srows = list(csv.DictReader(fh))
    assert len(srows) == 1 and srows[0]["speaker"] == "spk1" and int(srows[0]["n"]) == 15


def test_cli_energy_reports_missing_paths(tmp_path, capsys):
    from tonguevis.cli import main

    code = main(["energy", str(tmp_path / "nothing"), "--csv", str(tmp_path / "e.csv")])
    assert code == 2
    assert "no such file" in capsys.readouterr().err


def test_demo_vowel_windows_hold_the_release(demo_result):
    from tonguevis.analysis.energy import production_curves, vowel_windows

    motion = demo_result.motions["spk1_ka"]
    truth = TRUTH["files"]["spk1_ka.tsv"]["productions"]
    windows = [w for w in vowel_windows(SimpleNamespace(**p) for p in truth) if 2 <= w.index <= 4]
    curves = production_curves(motion, windows, recording="spk1_ka")
    assert len(curves) == 15
    for c in curves:
        inside = (c.extra["release_s"] - c.start) / (c.end - c.start)
        assert 0.2 < inside < 0.8  # the release sits inside the vowel-to-vowel span


def test_cli_energy_vowel_window(tmp_path, monkeypatch):
    from tonguevis.cli import energy as energy_cli
    from tonguevis.cli import main

    monkeypatch.setattr(energy_cli, "load_model", lambda args: box_tongue())
    out = tmp_path / "v.csv"
    assert main(["energy", str(DATA_DIR / "spk3_la.tsv"), "--csv", str(out), "--window", "vowel",
                 "--modes", str(MODES), "--landmarks", "rule", "--quiet"]) == 0
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    truth = {(p["train"], p["index"]): p for p in _truth_productions("spk3_la.tsv")}
    assert {tuple(map(int, r["production"].split("."))) for r in rows} == set(truth)
    for key, p in truth.items():
        times = [float(r["recording_time_s"]) for r in rows if r["production"] == f"{key[0]}.{key[1]}"]
        assert min(times) < p["release"] < max(times) <= p["vowel"] + 0.03


def test_walked_non_recordings_are_skipped_named_ones_fail(tmp_path, monkeypatch, capsys):
    import shutil

    from tonguevis.cli import energy as energy_cli
    from tonguevis.cli import main

    monkeypatch.setattr(energy_cli, "load_model", lambda args: box_tongue())
    for name in ("spk2_ra.tsv", "spk2_ra.wav", "sensor_map.json"):
        shutil.copy(DATA_DIR / name, tmp_path / name)
    (tmp_path / "energy_old.csv").write_text("recording,production,time_s\nx,1.2,0.1\n")  # an earlier output
    out = tmp_path / "out" / "e.csv"
    out.parent.mkdir()
    assert main(["energy", str(tmp_path), "--csv", str(out), "--modes", str(MODES), "--landmarks", "rule",
                 "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "skipped" in text and "energy_old.csv" in text and "15 production curves" in text
    code = main(["energy", str(tmp_path / "energy_old.csv"), "--csv", str(out), "--quiet"])
    assert code == 2 and "energy_old.csv" in capsys.readouterr().err


@pytest.mark.parametrize("name, speaker, syllable, trial", [
    ("006_OSN12_Kah_nofb_natural_take2_HR.tsv", "OSN12", "ka", 2),
    ("009_OSN12_Tah_withFb_natural_HR.tsv", "OSN12", "ta", 1),
    ("recording_07.tsv", "", "", 1),
])
def test_labels_from_names_in_no_fixed_layout(tmp_path, name, speaker, syllable, trial):
    """Issue 27, item 13: names not laid out like the demo's gave blank speaker and syllable columns."""
    entry = labels_from_name(tmp_path / name)
    assert (entry.speaker, entry.syllable, entry.trial) == (speaker, syllable, trial)


def test_cli_energy_takes_speaker_and_syllable_and_says_when_unknown(tmp_path, monkeypatch, capsys):
    """A name with no speaker or syllable: the command says so; --speaker/--syllable fill the columns."""
    import shutil

    from tonguevis.cli import energy as energy_cli
    from tonguevis.cli import main
    from tonguevis.render.energy import group_label

    monkeypatch.setattr(energy_cli, "load_model", lambda args: box_tongue())
    for source, target in (("spk1_ta.tsv", "recording_07.tsv"), ("spk1_ta.wav", "recording_07.wav"),
                           ("sensor_map.json", "sensor_map.json")):
        shutil.copy(DATA_DIR / source, tmp_path / target)
    out = tmp_path / "e.csv"
    common = ["energy", str(tmp_path / "recording_07.tsv"), "--csv", str(out), "--modes", str(MODES),
              "--landmarks", "rule", "--quiet"]
    assert main(common) == 0
    assert ("recording_07: speaker and syllable unknown (not in the file name or the labels; give --speaker NAME "
            "--syllable CV or --labels TABLE)") in capsys.readouterr().out
    assert group_label(("", ""), ("speaker", "syllable")) == "unknown speaker unknown syllable"

    assert main([*common, "--speaker", "P7", "--syllable", "TA"]) == 0
    assert "unknown" not in capsys.readouterr().out
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert rows and {(r["speaker"], r["syllable"]) for r in rows} == {("P7", "ta")}
