"""Trains from audio or kinematics; productions from the articulator's closures and releases."""

import csv

import numpy as np
import pytest

from tests.preprocess._synthetic import bump_release_times, recording, syllable_train_recording
from tonguevis.errors import RecordingError
from tonguevis.preprocess import ProductionTable, find_productions, find_trains
from tonguevis.preprocess.trains import active_spans, audio_envelope


def test_audio_envelope_levels():
    rate = 8000.0
    samples = np.concatenate([np.zeros(800), 0.5 * np.ones(800)])
    times, level = audio_envelope(samples, rate, frame=0.01)
    assert len(times) == 20
    assert times[0] == pytest.approx(0.005)
    assert level[0] == -120.0
    assert level[-1] == pytest.approx(20 * np.log10(0.5))


def test_active_spans_bridges_short_gaps():
    times = np.arange(20) * 0.1 + 0.05
    active = np.zeros(20, bool)
    active[[2, 3, 5, 6, 12, 13, 14]] = True
    spans = active_spans(times, active, 0.1, max_gap=0.15, min_duration=0.25)
    assert spans == [(pytest.approx(0.2), pytest.approx(0.7)), (pytest.approx(1.2), pytest.approx(1.5))]
    assert active_spans(times, active, 0.1, max_gap=0.05, min_duration=0.25) == [
        (pytest.approx(1.2), pytest.approx(1.5))]


def test_trains_from_audio_match_the_sound():
    rec, _, spans = syllable_train_recording()
    found = find_trains(rec)
    assert len(found) == len(spans)
    for (a, b), (ta, tb) in zip(found, spans):
        assert abs(a - ta) <= 0.011 and abs(b - tb) <= 0.011


def test_trains_from_kinematics_without_audio():
    rec, releases, _ = syllable_train_recording(with_audio=False)
    found = find_trains(rec)
    assert len(found) == len(releases)
    for (a, b), r in zip(found, releases):
        assert a < r[0] < r[-1] < b and b - a < (r[-1] - r[0]) + 0.5
    with pytest.raises(RecordingError, match="no audio"):
        find_trains(rec, use_audio=True)


def test_productions_release_to_release():
    rec, tops, spans = syllable_train_recording(noise=1e-4)
    releases = bump_release_times(tops)
    table = find_productions(rec, keep=None)
    assert len(table) == 15 and table.counts == [5, 5, 5] and not table.notes and table.clear
    found = table.as_array()
    np.testing.assert_allclose(found[:, 2], np.concatenate(releases), atol=0.01)  # within one frame
    np.testing.assert_array_equal(found[:, 2], found[:, 4])  # start is the release
    # the closure is the top of the bump, before the release
    np.testing.assert_allclose([p.closure for p in table], np.concatenate(tops), atol=0.015)
    assert all(p.closure < p.release for p in table)
    for p in table:
        r = releases[p.train - 1]
        expected_end = r[p.index] if p.index < 5 else spans[p.train - 1][1]
        assert p.end == pytest.approx(expected_end, abs=0.015)
        if p.index < 5:  # the vowel lies midway between two bumps
            top = tops[p.train - 1]
            assert p.vowel == pytest.approx((top[p.index - 1] + top[p.index]) / 2, abs=0.02)
        assert p.start < p.vowel <= p.end


def test_default_keeps_the_second_to_fourth():
    rec, tops, _ = syllable_train_recording()
    releases = bump_release_times(tops)
    table = find_productions(rec)
    assert [(p.train, p.index) for p in table] == [(t, i) for t in (1, 2, 3) for i in (2, 3, 4)]
    np.testing.assert_allclose([p.start for p in table], [r[i] for r in releases for i in (1, 2, 3)],
                               atol=0.01)


def test_a_short_train_is_reported():
    rec, _, _ = syllable_train_recording(syllables=4, trains=1)
    table = find_productions(rec, keep=None)
    assert table.counts == [4] and len(table) == 4
    # one train alone: nothing to compare its length with; the paper's rule still applies to it
    assert [p.index for p in find_productions(rec)] == [2, 3, 4]
    rec, _, _ = syllable_train_recording(syllables=[5, 4, 5], trains=3)
    table = find_productions(rec, keep=None)
    assert table.counts == [5, 4, 5]
    assert [n for n in table.notes if "train 2" in n and "4 productions, the other trains 5" in n]


def test_csv_round_trip(tmp_path):
    rec, _, _ = syllable_train_recording(trains=1)
    table = find_productions(rec)
    path = tmp_path / "out.csv"
    table.to_csv(path)
    with open(path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [int(r["index"]) for r in rows] == [2, 3, 4]
    assert float(rows[0]["start_s"]) == pytest.approx(table[0].start, abs=1e-4)
    assert rows[0]["label"] == "" and rows[0]["articulator"] == "TT"
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind
    assert isinstance(table, ProductionTable)


def test_no_articulator_raises():
    rec = recording({"JAW": np.zeros((100, 3))})
    with pytest.raises(RecordingError, match="tongue-tip"):
        find_productions(rec)
    with pytest.raises(RecordingError, match="no sensor 'TT'"):
        find_productions(recording({"TD": np.zeros((100, 3))}), articulator="TT")


def test_short_gaps_in_the_tip_do_not_lose_productions():
    rec, tops, _ = syllable_train_recording(trains=2)
    rec.sensors["TT"][[int(tops[0][2] * 100) + 8, int(tops[1][1] * 100) + 5]] = np.nan
    rec.sensors["TT"][int(tops[1][3] * 100) + 6: int(tops[1][3] * 100) + 9] = np.nan
    table = find_productions(rec, keep=None)
    assert table.counts == [5, 5]
    np.testing.assert_allclose([p.start for p in table], np.concatenate(bump_release_times(tops)), atol=0.015)


def test_noise_only_gives_no_productions_and_no_crash():
    rng = np.random.default_rng(0)
    rec = recording({"TT": rng.normal(0, 1e-4, (500, 3))})
    table = find_productions(rec, keep=None, trains=[(1.0, 2.0)])
    assert table.counts == [0] and len(table) == 0  # 0.1 mm noise has no 1 mm falls
    nan_rec = recording({"TT": np.full((300, 3), np.nan)})
    table = find_productions(nan_rec, trains=[(0.5, 1.5)])
    assert len(table) == 0 and "too few valid" in table.notes[0]
