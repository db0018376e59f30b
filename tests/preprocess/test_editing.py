"""Hand corrections of productions: move, add, delete, save beside the recording, used by every command."""

from __future__ import annotations

import numpy as np
import pytest

from tests.preprocess.test_gestures import isolated_repetitions
from tonguevis.errors import RecordingError
from tonguevis.io import write_recording
from tonguevis.io.recording import Recording
from tonguevis.preprocess.editing import ProductionEditor
from tonguevis.workflows import find_recording_productions, open_recording

STARTS = [2.5, 4.3, 6.0, 7.9]


@pytest.fixture
def saved(tmp_path):
    """A recording of four isolated /ta/ written as a file, and its path."""
    t, z, _ = isolated_repetitions(STARTS)
    tip = np.column_stack([np.zeros_like(t), np.zeros_like(t), z])
    rec = Recording(100.0, t, {"TT": tip}, metadata={"file": None})
    path = tmp_path / "S1_ta.csv"
    write_recording(rec, path)
    return path


def test_move_add_delete_and_save_beside_the_recording(saved):
    rec = open_recording(saved)
    table = find_recording_productions(rec, keep=None)
    assert len(table) == 4 and table.articulator == "TT"
    editor = ProductionEditor(rec, table, saved)
    # delete the third, then add it back by clicking near its closure: the finder's measures come back
    third = table[2]
    editor.delete(2)
    assert len(editor.table) == 3 and editor.edited
    editor.add(third.closure)
    assert len(editor.table) == 4
    assert editor.table[2].start == pytest.approx(third.start, abs=0.011)
    assert editor.table[2].end == pytest.approx(third.end, abs=0.011)
    # move the first one's end earlier and its start later; it cannot pass its neighbour
    editor.move_boundary(0, "end", table[0].end - 0.1)
    editor.move_boundary(0, "start", table[0].start + 0.05)
    assert editor.table[0].end == pytest.approx(table[0].end - 0.1)
    assert editor.table[0].start == pytest.approx(table[0].start + 0.05)
    editor.move_boundary(1, "start", 0.0)
    assert editor.table[1].start == pytest.approx(editor.table[0].end)
    assert all(p.label == "ta" for p in editor.table)
    with pytest.raises(RecordingError, match="inside production 2"):
        editor.add(editor.table[1].start + 0.01)
    path = editor.save()
    assert path == saved.with_suffix(".TextGrid") and not editor.edited
    # every command now reads them with the recording: the productions are the corrected ones
    again = find_recording_productions(open_recording(saved))
    assert [(round(p.start, 4), round(p.end, 4), p.label) for p in again] == [
        (round(p.start, 4), round(p.end, 4), "ta") for p in editor.table]
    assert again.articulator_reason == "labelled"
    assert sorted(f.name for f in saved.parent.iterdir()) == ["S1_ta.TextGrid", "S1_ta.csv"]


def test_a_recording_without_a_file_cannot_be_saved_beside_it():
    t, z, _ = isolated_repetitions(STARTS[:2])
    rec = Recording(100.0, t, {"TT": np.column_stack([0 * t, 0 * t, z])}, metadata={"file": None})
    editor = ProductionEditor(rec, find_recording_productions(rec, keep=None))
    with pytest.raises(RecordingError, match="no file"):
        editor.save()
