"""Dialogs: errors that name the file and the problem, opening a recording with its sound and
labels, and the sensor-mapping dialog."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import (QComboBox, QDialog, QDialogButtonBox, QFileDialog, QFormLayout, QHBoxLayout,
                               QLabel, QLineEdit, QMessageBox, QPushButton, QVBoxLayout, QWidget)

from tonguevis.workflows.session import ROLES, TONGUE_NAMES

IGNORE = "(not used)"


def error_box(parent, title: str, message: str, path=None) -> QMessageBox:
    """Show a non-blocking error dialog (the app keeps running) and return it."""
    text = message if path is None or str(path) in message else f"{path}:\n{message}"
    box = QMessageBox(QMessageBox.Icon.Critical, title, text, QMessageBox.StandardButton.Ok, parent)
    box.setModal(True)
    box.open()
    return box


def guess_role(channel: str) -> str:
    """A first guess of a channel's role from common spellings (the user confirms)."""
    upper = channel.upper().replace("_", "").replace(" ", "")
    for role, spellings in {
        "TT": ("TT", "TIP", "TONGUETIP", "TTIP"), "TB": ("TB", "BLADE", "TBL"),
        "TD": ("TD", "DORSUM", "TM", "MID", "TMID"), "TBK": ("TBK", "BACK", "TR", "REAR"),
        "JAW": ("JAW", "LI", "LOWERINCISOR", "JW"), "UL": ("UL", "UPPERLIP"), "LL": ("LL", "LOWERLIP"),
    }.items():
        if upper in spellings:
            return role
    return IGNORE


class SensorMapDialog(QDialog):
    """Ask which channel is which sensor when a file's channel names are not known.

    ``mapping()`` returns {canonical name: channel} for the channels given a role.
    """

    def __init__(self, channels: list[str], path=None, parent=None):
        super().__init__(parent)
        self.setWindowTitle("Which sensor is which?")
        layout = QVBoxLayout(self)
        where = f" in {path}" if path else ""
        layout.addWidget(QLabel(
            f"The channels{where} carry no known tongue sensor names ({', '.join(TONGUE_NAMES)}).\n"
            "Give each channel its role; at least one tongue sensor is needed to drive the model."))
        form = QFormLayout()
        self.boxes: dict[str, QComboBox] = {}
        for channel in channels:
            box = QComboBox()
            box.addItems([IGNORE, *ROLES])
            box.setCurrentText(guess_role(channel))
            form.addRow(channel, box)
            self.boxes[channel] = box
        layout.addLayout(form)
        self.problem = QLabel()
        self.problem.setStyleSheet("color: #c0392b")
        layout.addWidget(self.problem)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self._check_and_accept)
        buttons.rejected.connect(self.reject)
        layout.addWidget(buttons)

    def mapping(self) -> dict[str, str]:
        return {box.currentText(): channel for channel, box in self.boxes.items()
                if box.currentText() != IGNORE}

    def set_role(self, channel: str, role: str) -> None:
        self.boxes[channel].setCurrentText(role)

    def problem_text(self) -> str:
        roles = [box.currentText() for box in self.boxes.values() if box.currentText() != IGNORE]
        repeated = sorted({r for r in roles if roles.count(r) > 1})
        if repeated:
            return f"each role once: {', '.join(repeated)} given to several channels"
        if not any(r in TONGUE_NAMES for r in roles):
            return "give at least one channel a tongue role"
        return ""

    def _check_and_accept(self) -> None:
        problem = self.problem_text()
        self.problem.setText(problem)
        if not problem:
            self.accept()


class OpenRecordingDialog(QDialog):
    """File ▸ Open with sound/labels: a recording and, optionally, its WAV and Praat TextGrid.

    Left empty, the sound and labels are found as for every recording (a same-name
    ``.wav`` / ``.TextGrid`` beside it, Carstens ``pos``/``wav`` folders).
    """

    FIELDS = {
        "recording": ("Recording", "an EMA recording (required)", ""),
        "audio": ("Sound (WAV)", "found automatically: same name .wav beside it, or ../wav/ for ../pos/",
                  "WAV audio (*.wav *.WAV);;All files (*)"),
        "labels": ("Labels (TextGrid)", "found automatically: same name .TextGrid beside it",
                   "Praat TextGrid (*.TextGrid *.textgrid);;All files (*)"),
    }

    def __init__(self, folder: str | Path = "", parent=None):
        super().__init__(parent)
        self.setWindowTitle("Open a recording with its sound and labels")
        self.folder = str(folder)
        self.edits: dict[str, QLineEdit] = {}
        layout = QVBoxLayout(self)
        form = QFormLayout()
        for key, (title, hint, filter_) in self.FIELDS.items():
            edit = QLineEdit()
            edit.setPlaceholderText(hint)
            edit.setMinimumWidth(420)
            browse = QPushButton("Browse…")
            browse.clicked.connect(lambda _=False, k=key, f=filter_: self._browse(k, f))
            row = QWidget()
            box = QHBoxLayout(row)
            box.setContentsMargins(0, 0, 0, 0)
            box.addWidget(edit, 1)
            box.addWidget(browse)
            form.addRow(title, row)
            self.edits[key] = edit
        layout.addLayout(form)
        self.buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Open | QDialogButtonBox.StandardButton.Cancel)
        self.buttons.accepted.connect(self.accept)
        self.buttons.rejected.connect(self.reject)
        layout.addWidget(self.buttons)
        self.edits["recording"].textChanged.connect(self._update)
        self._update()

    def _update(self) -> None:
        ok = self.buttons.button(QDialogButtonBox.StandardButton.Open)
        ok.setEnabled(bool(self.edits["recording"].text().strip()))

    def _browse(self, key: str, filter_: str) -> None:
        start = self.edits[key].text() or self.edits["recording"].text() or self.folder
        path, _ = QFileDialog.getOpenFileName(self, self.FIELDS[key][0], str(Path(start).parent if
                                              Path(start).is_file() else start), filter_)
        if path:
            self.edits[key].setText(path)

    def set_paths(self, recording="", audio="", labels="") -> None:
        for key, value in (("recording", recording), ("audio", audio), ("labels", labels)):
            self.edits[key].setText(str(value or ""))

    def paths(self) -> tuple[str, str | None, str | None]:
        """(recording, sound file or None for automatic, TextGrid or None for automatic)."""
        text = {key: edit.text().strip() for key, edit in self.edits.items()}
        return text["recording"], text["audio"] or None, text["labels"] or None
