"""Simulation ▸ Set rest interval…: the dialog and the window's actions around it.

The rest pose (mean sensor positions over the rest interval) is what the
alignment, the jaw and head corrections and every displacement refer to.  The
app finds it as every front end does (:func:`tonguevis.workflows.simulate_recording`:
the longest still interval, else the stillest window) and says which in the
status bar; here the user gives one, and the recording is simulated again.
"""

from __future__ import annotations

from PySide6.QtWidgets import QDialog, QDialogButtonBox, QDoubleSpinBox, QFormLayout, QLabel, QVBoxLayout

from tonguevis.errors import TonguevisError
from tonguevis.gui.elastic_label import ElasticLabel

__all__ = ["RestIntervalDialog", "RestMixin"]


def _problem(exc: TonguevisError) -> str:
    """The error's message without the file name in front (the dialog is about that file)."""
    text = str(exc)
    return text[len(exc.path) + 2:] if exc.path and text.startswith(f"{exc.path}: ") else text


class RestIntervalDialog(QDialog):
    """Start and end of the rest interval (seconds), checked before it is accepted.

    ``interval()`` is the (start_s, end_s) chosen, or None after *Find automatically*.
    """

    def __init__(self, session, parent=None):
        super().__init__(parent)
        self.session = session
        self.automatic = False
        self.setWindowTitle("Rest interval")
        recording = session.recording
        t0, t1 = float(recording.times[0]), float(recording.times[-1])
        layout = QVBoxLayout(self)
        now = session.rest.describe().removeprefix("rest: ") if session.rest is not None else "none yet"
        intro = QLabel(
            "The rest pose is the mean sensor position over the rest interval: the model's alignment and "
            f"every displacement refer to it. {session.name} lasts {t0:.2f}-{t1:.2f} s.\n\nIn use: {now}.")
        intro.setWordWrap(True)
        layout.addWidget(intro)
        form = QFormLayout()
        start, end = self._initial(session)
        self.start, self.end = self._spin(t0, t1, start), self._spin(t0, t1, end)
        form.addRow("Start (s)", self.start)
        form.addRow("End (s)", self.end)
        layout.addLayout(form)
        self.problem = QLabel()
        self.problem.setWordWrap(True)
        self.problem.setStyleSheet("color: #c0392b")
        layout.addWidget(self.problem)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel)
        self.auto_button = buttons.addButton("Find automatically", QDialogButtonBox.ButtonRole.ResetRole)
        self.auto_button.setToolTip("the longest still interval of >= 1 s, else the stillest 0.2 s window")
        self.auto_button.clicked.connect(self._automatic)
        buttons.accepted.connect(self._check_and_accept)
        buttons.rejected.connect(self.reject)
        layout.addWidget(buttons)

    @staticmethod
    def _initial(session) -> tuple[float, float]:
        if session.given_rest is not None:
            return session.given_rest
        if session.rest is not None:
            return session.rest.interval
        t0 = float(session.recording.times[0])
        return t0, min(t0 + 1.0, float(session.recording.times[-1]))

    @staticmethod
    def _spin(low: float, high: float, value: float) -> QDoubleSpinBox:
        box = QDoubleSpinBox()
        box.setDecimals(2)
        box.setSingleStep(0.05)
        box.setRange(low, high)
        box.setSuffix(" s")
        box.setValue(value)
        return box

    def interval(self) -> tuple[float, float] | None:
        return None if self.automatic else (self.start.value(), self.end.value())

    def problem_text(self) -> str:
        """What is wrong with the interval entered ("" when it can serve as the rest)."""
        from tonguevis.preprocess.rest import check_rest_interval

        try:
            check_rest_interval(self.session.recording, (self.start.value(), self.end.value()),
                                self.session.rest_sensors())
        except TonguevisError as exc:
            return _problem(exc)
        return ""

    def _check_and_accept(self) -> None:
        problem = self.problem_text()
        self.problem.setText(problem)
        if not problem:
            self.automatic = False
            self.accept()

    def _automatic(self) -> None:
        self.automatic = True
        self.accept()


class RestMixin:
    """The window's rest actions; needs ``self.session``, ``self.controller``, ``self.show_error``."""

    def ask_rest_interval(self) -> None:
        """Simulation ▸ Set rest interval…: ask, then simulate again with the answer."""
        if self.session is None:
            self.show_error("No recording", "open a recording first; its rest interval can then be set")
            return
        dialog = RestIntervalDialog(self.session, self)
        dialog.accepted.connect(lambda: self.set_rest_interval(dialog.interval()))
        self.last_dialog = dialog
        dialog.open()

    def set_rest_interval(self, interval: tuple[float, float] | None) -> bool:
        """Use ``interval`` (start_s, end_s) as the rest, or None to find it; re-simulate in the worker.

        A bad interval shows a dialog naming the problem and changes nothing; returns whether it was used.
        """
        from tonguevis.preprocess.rest import check_rest_interval

        session = self.session
        if session is None:
            self.show_error("No recording", "open a recording first; its rest interval can then be set")
            return False
        if interval is not None:
            try:
                interval = check_rest_interval(session.recording, interval, session.rest_sensors())
            except TonguevisError as exc:
                self.show_error("Rest interval not usable", str(exc), session.path)
                return False
        session.given_rest = interval
        self.controller.resimulate()
        return True

    def _build_rest_status(self) -> None:
        self.rest_label = ElasticLabel("", minimum_width=160)  # the rest line, kept in view; elided when narrow
        self.rest_label.setToolTip("the rest interval of the simulation and how it was found "
                                   "(Simulation ▸ Set rest interval… to give another)")
        self.statusBar().addPermanentWidget(self.rest_label)

    def show_rest(self, session) -> None:
        """The rest line in the status bar's permanent corner (blank before a simulation)."""
        label = getattr(self, "rest_label", None)
        if label is not None:
            label.setText(session.rest.describe() if session is not None and session.rest is not None else "")
