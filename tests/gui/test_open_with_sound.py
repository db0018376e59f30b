"""Opening a recording with a sound file and a TextGrid of one's choice: the dialog, the window, the CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("PySide6")

from tonguevis.io import Audio, Label  # noqa: E402
from tonguevis.io.textgrid import write_textgrid  # noqa: E402
from tonguevis.io.wav import write_wav  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


def files(folder: Path):
    """A 2 s recording with a TT sensor (CSV), and a WAV and a TextGrid under other names elsewhere."""
    from tests.gui.fakes import fake_recording
    from tonguevis.io import write_recording

    rec = fake_recording(names=("TT", "TD", "TL", "TR"))
    recording = folder / "take.csv"
    write_recording(rec, recording)
    other = folder / "elsewhere"
    other.mkdir()
    wav = other / "microphone.wav"
    write_wav(Audio(0.2 * np.sin(np.arange(32000) / 7.0), 16000.0), wav)
    grid = other / "annotation.TextGrid"
    write_textgrid([Label(0.2, 0.7, "ta", "syll"), Label(0.7, 1.2, "ta", "syll")], grid, end=2.0)
    return recording, wav, grid


def test_dialog_gives_the_recording_and_optional_files(qtbot, tmp_path):
    from PySide6.QtWidgets import QDialogButtonBox

    from tonguevis.gui.dialogs import OpenRecordingDialog

    dialog = OpenRecordingDialog(tmp_path)
    qtbot.addWidget(dialog)
    open_button = dialog.buttons.button(QDialogButtonBox.StandardButton.Open)
    assert not open_button.isEnabled()  # no recording yet
    dialog.set_paths(recording=tmp_path / "take.csv")
    assert open_button.isEnabled()
    assert dialog.paths() == (str(tmp_path / "take.csv"), None, None)  # sound and labels: found automatically
    dialog.set_paths(tmp_path / "take.csv", tmp_path / "a.wav", tmp_path / "b.TextGrid")
    assert dialog.paths() == (str(tmp_path / "take.csv"), str(tmp_path / "a.wav"), str(tmp_path / "b.TextGrid"))


def test_open_with_sound_and_labels_from_the_file_menu(qtbot, window, tmp_path):
    recording, wav, grid = files(tmp_path)
    actions = {a.text(): a for a in window.menuBar().actions()[0].menu().actions()}
    assert "Open recording with &sound/labels…" in actions
    actions["Open recording with &sound/labels…"].trigger()
    dialog = window.last_dialog
    dialog.set_paths(recording, wav, grid)
    dialog.accept()
    session = window.session
    assert session is not None and session.path == recording
    assert session.recording.metadata["audio_file"] == str(wav)
    assert session.recording.audio.rate == 16000
    assert [lab.text for lab in session.recording.labels] == ["ta", "ta"]
    assert window.audio.n_tiers == 1
    window.controller.stop("primary")


def test_a_missing_sound_file_is_an_error_dialog(qtbot, window, tmp_path):
    recording, _, _ = files(tmp_path)
    assert not window.open_recording(recording, audio=tmp_path / "gone.wav")
    assert "gone.wav" in window.statusBar().currentMessage()


def test_view_command_passes_audio_and_labels(monkeypatch, tmp_path):
    import tonguevis.gui.app as app
    from tonguevis.cli import main

    seen = {}
    monkeypatch.setattr(app, "run_view", lambda *args, **kw: seen.update(kw) or 0)
    assert main(["view", str(tmp_path / "take.csv"), "--audio", "a.wav", "--labels", "b.TextGrid"]) == 0
    assert seen["reading"]["audio"] == Path("a.wav") and seen["reading"]["labels"] == Path("b.TextGrid")


def test_create_window_opens_with_the_given_sound(qtbot, tmp_path, settings):
    from tonguevis.gui.app import create_window

    recording, wav, grid = files(tmp_path)
    window = create_window(recording, preferences=settings, feature_tabs=False, reading={"audio": wav, "labels": grid})
    qtbot.addWidget(window)
    try:
        assert window.session.recording.metadata["audio_file"] == str(wav)
        assert window.session.recording.metadata["labels_file"] == str(grid)
    finally:
        window.controller.stop("primary")
        window.close()


def test_export_video_reads_the_given_sound(monkeypatch, tmp_path):
    import tonguevis.workflows.session as session_module
    from tonguevis.cli import main

    seen = {}

    class Stop(Exception):
        pass

    def load_session(path, **kw):
        seen.update(kw)
        raise Stop

    monkeypatch.setattr(session_module, "load_session", load_session)
    with pytest.raises(Stop):
        main(["export-video", str(tmp_path / "take.csv"), "--out", str(tmp_path / "v.mp4"), "--audio", "a.wav"])
    assert seen["audio"] == Path("a.wav")
