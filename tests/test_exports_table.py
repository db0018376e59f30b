"""One export table (issue 24, item 1): tonguevis formats prints it, write_export writes from a session."""

from __future__ import annotations

import csv

import pytest

from tonguevis.cli import main
from tonguevis.paths import DATA_DIR
from tonguevis.workflows.exports import EXPORTS, export_format, exports_text, write_export

DEMO = DATA_DIR / "spk1_ta.tsv"


def test_the_table_names_every_format_once():
    keys = [fmt.key for fmt in EXPORTS]
    assert sorted(keys) == ["csv", "mp4", "png", "textgrid", "vtk", "wav", "xdmf"] and len(set(keys)) == len(keys)
    text = exports_text()
    for fmt in EXPORTS:
        assert fmt.command in text and f"File ▸ Export ▸ {fmt.title}" in text
    with pytest.raises(ValueError, match="unknown export 'gif'"):
        export_format("gif")


def test_tonguevis_formats_prints_readers_and_exports(capsys):
    assert main(["formats"]) == 0
    out = capsys.readouterr().out
    assert "ndi_wave" in out and "mview" in out
    for fmt in EXPORTS:
        assert fmt.title in out
    assert main(["formats", "--exports"]) == 0
    assert "ndi_wave" not in capsys.readouterr().out


def test_productions_written_from_a_session_read_back(tmp_path):
    from tonguevis.io.textgrid import read_textgrid
    from tonguevis.workflows.session import load_session

    session = load_session(DEMO)
    table = session.production_table
    out = write_export("csv", session, tmp_path / "p.csv")
    rows = list(csv.DictReader(open(out)))
    assert len(rows) == len(table) > 0
    assert [float(r["start_s"]) for r in rows] == pytest.approx([p.start for p in table], abs=1e-4)  # 0.1 ms in the CSV
    grid = write_export("textgrid", session, tmp_path / "p.TextGrid")
    tiers = {label.tier for label in read_textgrid(grid)}
    assert "productions" in tiers


def test_a_motion_export_needs_a_simulation_and_png_is_the_apps(tmp_path):
    from tonguevis.errors import TonguevisError
    from tonguevis.workflows.session import load_session

    session = load_session(DEMO)
    with pytest.raises(TonguevisError, match="simulate the recording first"):
        write_export("mp4", session, tmp_path / "v.mp4")
    session.motion = object()
    with pytest.raises(TonguevisError, match="window"):
        write_export("png", session, tmp_path / "p.png")
