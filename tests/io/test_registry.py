"""Dispatch: content first, then extension; unknown files list what is supported."""

from __future__ import annotations

import pytest

from tonguevis.io import (
    FORMATS, RecordingError, detect_format, read_recording, registered_formats, supported_formats, write_recording,
)
from tests.io.synthetic import make_recording


def test_every_format_registers_reader_and_sniffer():
    formats = registered_formats()
    assert formats == FORMATS and "csv" in supported_formats()
    assert set(FORMATS) == {"ndi_wave", "optispeech", "carstens", "est_track", "mview", "bvh", "csv"}
    assert {n for n, f in FORMATS.items() if f.write} == {"ndi_wave", "bvh", "csv"}
    for fmt in FORMATS.values():
        assert fmt.read is not None and fmt.extensions and fmt.description
        assert fmt.sniff(b"", None) is False  # no format claims an empty file


def test_unknown_file_lists_supported_formats(tmp_path):
    path = tmp_path / "notes.txt"
    path.write_text("hello\nworld\n")
    with pytest.raises(RecordingError) as info:
        read_recording(path)
    message = str(info.value)
    assert str(path) in message and "unknown recording format" in message
    for name in FORMATS:
        assert name in message


def test_missing_file_folder_and_forced_format(tmp_path):
    with pytest.raises(RecordingError, match="no such file"):
        read_recording(tmp_path / "absent.tsv")
    with pytest.raises(RecordingError, match="folder"):
        read_recording(tmp_path)
    rec = make_recording(names=("S1",), audio_rate=None)
    write_recording(rec, tmp_path / "x.csv")
    assert read_recording(tmp_path / "x.csv", format="csv").metadata["format"] == "csv"
    with pytest.raises(RecordingError, match="not a number|expected|header"):
        read_recording(tmp_path / "x.csv", format="ndi_wave")
    with pytest.raises(RecordingError, match="no reader for format 'nope'"):
        read_recording(tmp_path / "x.csv", format="nope")


def test_extension_decides_when_content_has_no_signature(tmp_path):
    path = tmp_path / "headerless.pos"
    path.write_bytes(b"\x00" * (12 * 28 * 2))
    assert detect_format(path).name == "carstens"
    assert read_recording(path).n_samples == 2


def test_write_refuses_unknown_extension(tmp_path):
    with pytest.raises(RecordingError, match="writable formats"):
        write_recording(make_recording(), tmp_path / "x.pos")


def test_writes_are_atomic(tmp_path, monkeypatch):
    """A writer that fails half-way leaves neither a partial file nor a temporary one."""
    from pathlib import Path

    target = tmp_path / "x.csv"
    target.write_text("old content")
    rec = make_recording(names=("S1",), audio_rate=None)
    real_write_text = Path.write_text

    def half_then_fail(self, text, *args, **kwargs):
        real_write_text(self, text[: len(text) // 2], *args, **kwargs)
        raise OSError("disk full")

    monkeypatch.setattr(Path, "write_text", half_then_fail)
    with pytest.raises(OSError, match="disk full"):
        write_recording(rec, target)
    monkeypatch.undo()
    assert target.read_text() == "old content"
    assert [p.name for p in tmp_path.iterdir()] == ["x.csv"]
