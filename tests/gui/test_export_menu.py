"""File ▸ Export is built from the export table (issue 24, item 1): one item per format, each working."""

from __future__ import annotations

import csv

import pytest

from tonguevis.workflows.exports import EXPORTS

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


def test_the_export_menu_lists_the_table_and_writes_productions(qtbot, window, tmp_path, monkeypatch):
    from PySide6.QtWidgets import QFileDialog

    from tests.gui.conftest import demo_session

    file_menu = window.menuBar().actions()[0].menu()
    export = next(a.menu() for a in file_menu.actions() if a.text() == "&Export")
    assert [a.text() for a in export.actions()] == [f"{fmt.title}…" for fmt in EXPORTS]
    for fmt in EXPORTS:
        assert fmt.command in window.export_actions[fmt.key].toolTip()

    window.state.set_session(demo_session(), "primary", window)
    out = tmp_path / "productions.csv"
    monkeypatch.setattr(QFileDialog, "getSaveFileName", lambda *a, **k: (str(out), ""))
    window.export_actions["csv"].trigger()
    rows = list(csv.DictReader(open(out)))
    assert len(rows) == len(window.session.production_table) > 0
    assert window.state.status == f"saved {out}"
    grid = tmp_path / "productions.TextGrid"
    monkeypatch.setattr(QFileDialog, "getSaveFileName", lambda *a, **k: (str(grid), ""))
    window.export_actions["textgrid"].trigger()
    assert "productions" in grid.read_text()


def test_the_ema_for_praat_item_writes_the_wav_and_its_sidecar(qtbot, window, tmp_path, monkeypatch):
    """Issue 35: File ▸ Export ▸ EMA for Praat writes what tonguevis export-wav writes."""
    import json

    from PySide6.QtWidgets import QFileDialog
    from scipy.io import wavfile

    from tests.gui.conftest import demo_session

    session = demo_session()
    window.state.set_session(session, "primary", window)
    out = tmp_path / "ema.wav"
    monkeypatch.setattr(QFileDialog, "getSaveFileName", lambda *a, **k: (str(out), ""))
    window.export_actions["wav"].trigger()
    rate, data = wavfile.read(out)
    names = [c["name"] for c in json.loads(out.with_suffix(".json").read_text())["channels"]]
    assert rate == 16000 and data.shape[1] == len(names) == 1 + 3 * len(session.recording.sensor_names)
    assert window.state.status == f"saved {out}"
