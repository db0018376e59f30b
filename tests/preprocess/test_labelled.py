"""Productions from a label tier, and productions as label tiers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Label, Recording
from tonguevis.preprocess.labelled import production_labels, productions_from_tier
from tonguevis.preprocess.productions import Production, ProductionTable


def recording(labels) -> Recording:
    times = np.arange(300) / 100.0
    tip = np.column_stack([np.zeros(300), np.zeros(300), 0.01 * np.cos(2 * np.pi * times)])  # lowest at 0.5, 1.5, 2.5 s
    return Recording(100.0, times, {"TT": tip}, labels=list(labels), metadata={"file": "take.pos"})


SYLLABLES = [Label(0.2, 0.9, "ta", "syll"), Label(0.9, 1.8, "ta", "syll"), Label(2.1, 2.9, "ka", "syll"),
             Label(0.0, 3.0, "whole", "words"), Label(1.0, 1.0, "click", "events")]


def test_non_empty_intervals_become_productions_and_touching_ones_a_train():
    table = productions_from_tier(recording(SYLLABLES), "syll")
    assert [(p.train, p.index, p.start, p.end, p.release) for p in table] == [
        (1, 1, 0.2, 0.9, 0.2), (1, 2, 0.9, 1.8, 0.9), (2, 1, 2.1, 2.9, 2.1)]
    assert table.trains == [(0.2, 1.8), (2.1, 2.9)]
    assert table.counts == [2, 1]
    # the vowel: the tip's lowest point inside each interval
    assert [p.vowel for p in table] == pytest.approx([0.5, 1.5, 2.5])


def test_empty_texts_are_not_productions():
    labels = [Label(0.2, 0.9, "ta", "syll"), Label(0.9, 1.1, " ", "syll"), Label(1.1, 1.8, "ta", "syll")]
    table = productions_from_tier(recording(labels), "syll")
    assert [(p.start, p.end) for p in table] == [(0.2, 0.9), (1.1, 1.8)]
    assert [(p.train, p.index) for p in table] == [(1, 1), (2, 1)]


def test_without_a_tip_sensor_the_vowel_is_nan():
    rec = recording(SYLLABLES).renamed({"TT": "X"})
    table = productions_from_tier(rec, "syll")
    assert len(table) == 3 and all(math.isnan(p.vowel) for p in table)


def test_a_missing_tier_is_an_error_listing_the_tiers():
    with pytest.raises(RecordingError, match=r"no label tier 'syllables'.*tiers: syll, words, events"):
        productions_from_tier(recording(SYLLABLES), "syllables")
    with pytest.raises(RecordingError, match="--labels"):
        productions_from_tier(recording([]), "syll")


def test_a_point_tier_is_refused():
    with pytest.raises(RecordingError, match="'events' is a point tier"):
        productions_from_tier(recording(SYLLABLES), "events")


def test_production_labels_interval_and_point_tiers():
    table = ProductionTable([Production(1, 2, 0.5, 0.9, 0.5, 0.7), Production(1, 3, 0.9, 1.3, 0.9, float("nan"))])
    labels = production_labels(table)
    assert labels == [Label(0.5, 0.9, "1.2", "productions"), Label(0.9, 1.3, "1.3", "productions"),
                      Label(0.5, 0.5, "release", "events"), Label(0.7, 0.7, "vowel", "events"),
                      Label(0.9, 0.9, "release", "events")]
    # read back as a tier, they give the same spans
    back = productions_from_tier(recording(labels), "productions")
    assert [(p.start, p.end) for p in back] == [(0.5, 0.9), (0.9, 1.3)]


def test_workflow_takes_productions_from_a_tier_instead_of_finding_them():
    from tonguevis.workflows import find_recording_productions

    rec = recording(SYLLABLES)
    table = find_recording_productions(rec, tier="syll")
    assert [(p.start, p.end) for p in table] == [(0.2, 0.9), (0.9, 1.8), (2.1, 2.9)]
    with pytest.raises(RecordingError, match="tiers: syll, words, events"):
        find_recording_productions(rec, tier="phones")


def test_silence_labels_are_skipped_and_labels_carried():
    words = [Label(0.0, 0.2, "sp", "words"), Label(0.2, 0.9, "the", "words"), Label(0.9, 1.1, "<p:>", "words"),
             Label(1.1, 1.8, "birch", "words"), Label(1.8, 2.0, "SIL", "words"), Label(2.0, 2.4, "pau", "words"),
             Label(2.4, 2.9, "canoe", "words")]
    table = productions_from_tier(recording(words), "words")
    assert [p.label for p in table] == ["the", "birch", "canoe"]
    assert [p.name for p in table] == ["1.1 the", "2.1 birch", "3.1 canoe"]  # silences split the trains
    assert "3 labelled intervals" in table.notes[0] and "4 silence or empty intervals skipped" in table.notes[0]
    only_silence = [Label(0.0, 1.0, "sil", "words"), Label(1.0, 2.0, "sp", "words")]
    with pytest.raises(RecordingError, match="only silence labels"):
        productions_from_tier(recording(only_silence), "words")


def test_our_own_train_index_texts_are_not_labels():
    labels = [Label(0.2, 0.9, "1.1", "productions"), Label(0.9, 1.8, "1.2", "productions")]
    assert [p.label for p in productions_from_tier(recording(labels), "productions")] == ["", ""]


def test_a_productions_tier_beside_the_recording_wins(tmp_path):
    from tonguevis.workflows import find_recording_productions

    labels = [Label(0.2, 0.9, "ta", "productions"), Label(1.2, 1.8, "ta", "productions")]
    rec = recording(labels)
    table = find_recording_productions(rec)
    assert [(p.start, p.end, p.label) for p in table] == [(0.2, 0.9, "ta"), (1.2, 1.8, "ta")]
    found = find_recording_productions(rec, labelled=False, keep=None)  # found from the motion instead
    assert [p.start for p in found] != [0.2, 1.2] and found.articulator_reason != "labelled"
