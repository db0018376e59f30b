"""Sound and labels found beside a recording or given, the same way for every format."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from tests.conftest import shared_file
from tests.io.examples import MAKERS, make_ag501, make_mview_v5
from tonguevis.io import Audio, Label, RecordingError, read_recording
from tonguevis.io.textgrid import read_textgrid, write_textgrid
from tonguevis.io.wav import write_wav


def tone(seconds: float, rate: float = 8000.0) -> Audio:
    t = np.arange(int(round(seconds * rate))) / rate
    return Audio(samples=0.3 * np.sin(2 * np.pi * 200.0 * t), rate=rate)


def ag501(folder, seconds: float = 1.0):
    """A Carstens AG501 .pos of ``seconds`` at 250 Hz."""
    folder.mkdir(parents=True, exist_ok=True)
    return make_ag501(folder, n_frames=int(round(250 * seconds))).path


# ------------------------------------------------------------------ audio
def test_carstens_ag501_with_a_wav_beside_it_opens_with_sound(tmp_path):
    pos = ag501(tmp_path)
    write_wav(tone(1.0), pos.with_suffix(".wav"))
    rec = read_recording(pos)
    assert rec.metadata["format"] == "carstens"
    assert rec.audio is not None and rec.audio.rate == 8000
    assert rec.audio.duration == pytest.approx(1.0)
    assert rec.audio.offset == 0.0
    assert rec.metadata["audio_file"] == str(pos.with_suffix(".wav"))
    assert read_recording(pos, audio=False).audio is None


def test_wav_suffix_in_any_case(tmp_path):
    pos = ag501(tmp_path)
    write_wav(tone(1.0), tmp_path / f"{pos.stem}.Wav")
    rec = read_recording(pos)
    assert rec.audio is not None
    assert rec.metadata["audio_file"].endswith(".Wav")


def test_a_wav_of_another_stem_is_not_paired(tmp_path):
    pos = ag501(tmp_path)
    write_wav(tone(1.0), tmp_path / "other.wav")
    rec = read_recording(pos)
    assert rec.audio is None and rec.metadata["audio_file"] is None


def test_carstens_pos_and_wav_folders(tmp_path):
    session = tmp_path / "speaker1"
    pos = ag501(session / "pos")
    (session / "wav").mkdir()
    write_wav(tone(1.0), session / "wav" / f"{pos.stem}.wav")
    rec = read_recording(pos)
    assert rec.audio is not None
    assert rec.metadata["audio_file"] == str(session / "wav" / f"{pos.stem}.wav")


def test_wav_folder_is_only_looked_up_from_a_pos_folder(tmp_path):
    session = tmp_path / "speaker1"
    pos = ag501(session / "kinematics")
    (session / "wav").mkdir()
    write_wav(tone(1.0), session / "wav" / f"{pos.stem}.wav")
    assert read_recording(pos).audio is None


@pytest.mark.parametrize("name", sorted(k for k in MAKERS if not k.startswith("mview")))
def test_every_format_pairs_a_wav_beside_it(name, tmp_path):
    example = MAKERS[name](tmp_path)
    wav = example.path.with_suffix(".wav")
    if wav.exists():
        wav.unlink()  # the NDI writer's own WAV; use ours
    first = read_recording(example.path, **example.options)
    write_wav(tone(first.duration, rate=4000.0), wav)
    rec = read_recording(example.path, **example.options)
    assert rec.audio is not None and rec.audio.rate == 4000
    assert rec.metadata["audio_file"] == str(wav)


def test_explicit_audio_file(tmp_path):
    pos = ag501(tmp_path)
    elsewhere = tmp_path / "sound" / "take.wav"
    elsewhere.parent.mkdir()
    write_wav(tone(1.0, rate=16000.0), elsewhere)
    rec = read_recording(pos, audio=elsewhere)
    assert rec.audio.rate == 16000
    assert rec.metadata["audio_file"] == str(elsewhere)
    assert read_recording(pos, audio=str(elsewhere)).audio.rate == 16000


def test_missing_explicit_audio_file_is_an_error_naming_it(tmp_path):
    pos = ag501(tmp_path)
    missing = tmp_path / "nowhere.wav"
    with pytest.raises(RecordingError, match="nowhere.wav"):
        read_recording(pos, audio=missing)


def test_length_mismatch_warns_with_both_durations(tmp_path, caplog):
    pos = ag501(tmp_path, seconds=2.0)
    write_wav(tone(3.0), pos.with_suffix(".wav"))
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        rec = read_recording(pos)
    messages = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(messages) == 1, messages
    assert "3.000 s" in messages[0] and "2.000 s" in messages[0]
    assert "audio" in messages[0]
    assert "3.000 s" in rec.metadata["audio_mismatch"]


def test_a_small_length_difference_does_not_warn(tmp_path, caplog):
    pos = ag501(tmp_path, seconds=2.0)
    write_wav(tone(2.05), pos.with_suffix(".wav"))  # 50 ms: 2.5 %, under 0.5 s
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        rec = read_recording(pos)
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert "audio_mismatch" not in rec.metadata


def test_mismatch_over_five_percent_of_a_short_recording_warns(tmp_path, caplog):
    pos = ag501(tmp_path, seconds=2.0)
    write_wav(tone(2.3), pos.with_suffix(".wav"))  # 0.3 s: under 0.5 s but 15 %
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        read_recording(pos)
    assert any("2.300 s" in r.getMessage() for r in caplog.records if r.levelno == logging.WARNING)


def test_mview_keeps_its_embedded_audio(tmp_path):
    example = make_mview_v5(tmp_path)
    write_wav(tone(5.0, rate=16000.0), example.path.with_suffix(".wav"))  # a WAV beside does not replace it
    rec = read_recording(example.path)
    assert rec.audio is not None and rec.audio.rate == 8000
    assert rec.metadata["audio_source"] == "embedded"
    # an explicit file does, and audio=False drops even the embedded channel
    assert read_recording(example.path, audio=example.path.with_suffix(".wav")).audio.rate == 16000
    assert read_recording(example.path, audio=False).audio is None


def test_ndi_wave_reader_no_longer_pairs_by_itself(tmp_path):
    """The pairing lives in read_recording: the NDI reader alone gives the TSV only."""
    from tonguevis.io.ndi_wave import read_ndi_wave

    example = MAKERS["ndi_wave"](tmp_path)
    assert example.path.with_suffix(".wav").exists()
    assert read_ndi_wave(example.path).audio is None
    assert read_recording(example.path).audio is not None


# ------------------------------------------------------------------ labels
def praat_grid(path, tiers):
    """A TextGrid written by praatio itself (independent of our writer)."""
    from praatio import textgrid
    from praatio.data_classes.interval_tier import IntervalTier
    from praatio.data_classes.point_tier import PointTier

    grid = textgrid.Textgrid(0.0, 2.0)
    for name, kind, entries in tiers:
        cls = IntervalTier if kind == "interval" else PointTier
        grid.addTier(cls(name, entries, 0.0, 2.0))
    grid.save(str(path), format="long_textgrid", includeBlankSpaces=True)
    return path


WORDS = [(0.1, 0.5, "the"), (0.5, 0.9, "birch"), (1.2, 1.6, "canoe")]
EVENTS = [(0.3, "release"), (0.7, "vowel")]


def test_read_textgrid_written_by_praatio(tmp_path):
    grid = praat_grid(tmp_path / "a.TextGrid", [("words", "interval", WORDS), ("events", "point", EVENTS)])
    labels = read_textgrid(grid)
    assert labels == [Label(s, e, t, "words") for s, e, t in WORDS] + [Label(t, t, x, "events") for t, x in EVENTS]


def test_textgrid_round_trip(tmp_path):
    labels = [Label(s, e, t, "words") for s, e, t in WORDS] + [Label(t, t, x, "events") for t, x in EVENTS]
    out = tmp_path / "out.TextGrid"
    write_textgrid(labels, out, start=0.0, end=2.0)
    assert read_textgrid(out) == labels
    # and praatio reads it with the right tier kinds and span
    from praatio import textgrid

    grid = textgrid.openTextgrid(str(out), includeEmptyIntervals=False)
    assert grid.tierNames == ("words", "events")
    assert type(grid.getTier("events")).__name__ == "PointTier"
    assert (grid.minTimestamp, grid.maxTimestamp) == (0.0, 2.0)
    assert not list(tmp_path.glob(".*tmp*")), "the atomic write left its temporary file"


def test_write_textgrid_refuses_overlapping_intervals(tmp_path):
    labels = [Label(0.1, 0.6, "a", "w"), Label(0.5, 0.9, "b", "w")]
    with pytest.raises(RecordingError, match="overlap"):
        write_textgrid(labels, tmp_path / "x.TextGrid")
    assert not (tmp_path / "x.TextGrid").exists()


def test_textgrid_beside_the_recording_is_read(tmp_path):
    pos = ag501(tmp_path, seconds=2.0)
    praat_grid(tmp_path / f"{pos.stem}.textgrid", [("words", "interval", WORDS), ("events", "point", EVENTS)])
    rec = read_recording(pos)
    assert [lab.tier for lab in rec.labels] == ["words"] * 3 + ["events"] * 2
    assert rec.labels[1] == Label(0.5, 0.9, "birch", "words")
    assert rec.metadata["labels_file"].endswith(".textgrid")
    assert read_recording(pos, labels=False).labels == []


def test_explicit_labels_file_and_missing_one(tmp_path):
    pos = ag501(tmp_path, seconds=2.0)
    grid = praat_grid(tmp_path / "annotations.TextGrid", [("syll", "interval", WORDS)])
    assert read_recording(pos).labels == []
    rec = read_recording(pos, labels=grid)
    assert [lab.text for lab in rec.labels] == ["the", "birch", "canoe"]
    with pytest.raises(RecordingError, match="gone.TextGrid"):
        read_recording(pos, labels=tmp_path / "gone.TextGrid")


@pytest.mark.parametrize("content", ["", "garbage\n", 'File type = "ooTextFile"\nObject class = "TextGrid"\n'
                                     "xmin = 0\nxmax = 2\ntiers? <exists>\nsize = 1\nitem []:\n"])
def test_malformed_textgrid_is_a_recording_error_naming_the_file(tmp_path, content):
    pos = ag501(tmp_path)
    bad = tmp_path / f"{pos.stem}.TextGrid"
    bad.write_text(content)
    with pytest.raises(RecordingError, match=f"{pos.stem}.TextGrid"):
        read_recording(pos)


def test_textgrid_tiers_join_mview_tiers_and_replace_same_names(tmp_path):
    example = make_mview_v5(tmp_path)
    own = read_recording(example.path).labels
    assert {lab.tier for lab in own} == {"words", "phones"}
    praat_grid(example.path.with_suffix(".TextGrid"), [("phones", "interval", [(0.05, 0.1, "t")]),
                                                       ("notes", "point", [(0.1, "click")])])
    rec = read_recording(example.path)
    assert [lab for lab in rec.labels if lab.tier == "words"] == [lab for lab in own if lab.tier == "words"]
    assert [lab for lab in rec.labels if lab.tier == "phones"] == [Label(0.05, 0.1, "t", "phones")]
    assert [lab for lab in rec.labels if lab.tier == "notes"] == [Label(0.1, 0.1, "click", "notes")]


def test_haskins_mview_words_and_phones_are_tiers(tmp_path):
    path = shared_file("ema", "mview", "F01_B01_S01_R01_N.mat")
    rec = read_recording(path)
    tiers = {lab.tier for lab in rec.labels}
    assert tiers == {"words", "phones"}
    words = [lab.text.lower() for lab in rec.labels if lab.tier == "words"]
    for word in ("birch", "canoe", "planks"):
        assert word in words
    # written out for Praat and read back, the tiers are the same
    out = tmp_path / "haskins.TextGrid"
    write_textgrid(rec.labels, out, start=0.0, end=max(rec.duration, rec.audio.duration))
    back = read_textgrid(out)
    for tier in ("words", "phones"):
        mine = [(round(x.start, 6), round(x.end, 6), x.text) for x in rec.labels if x.tier == tier and x.text.strip()]
        theirs = [(round(x.start, 6), round(x.end, 6), x.text) for x in back if x.tier == tier]
        assert mine == theirs
