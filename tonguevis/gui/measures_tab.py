"""The Measures tab: the productions' measures of the open recording, and the repetitions of those selected.

Top: the palate the constriction is measured against (the run's speaker palate when one is set,
the generic one placed in the speaker, or none) and Save table….  Middle: one row per production
(:mod:`tonguevis.analysis.measures`; units in every header), following the primary recording and its
productions as they are edited; double-click a row to move the cursor to its closure.  Bottom: the
STI of every sensor over the selected productions (all when none is selected) and their
time-normalised mean ± SD trajectories (:mod:`tonguevis.render.repetitions`).  The tab only shows
what :func:`tonguevis.workflows.measures.measure_table` computes (no simulation is needed), run through
the app's job runner.
"""

from __future__ import annotations

import math
from pathlib import Path

from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure
from PySide6 import QtCore, QtWidgets

from tonguevis.appstate import connected
from tonguevis.errors import TonguevisError

from tonguevis._logging import logger

#: The table's columns: (key of the measures row, header).
COLUMNS = (("production", "production"), ("label", "label"), ("articulator", "articulator"),
           ("closure_s", "closure (s)"), ("constriction_degree_mm", "constriction\ndegree (mm)"),
           ("constriction_location_mm", "constriction\nlocation (mm)"),
           ("peak_velocity_closing_mm_s", "peak velocity\nclosing (mm/s)"),
           ("displacement_closing_mm", "displacement\nclosing (mm)"), ("stiffness_closing_per_s", "stiffness\nclosing (1/s)"),
           ("peak_velocity_opening_mm_s", "peak velocity\nopening (mm/s)"),
           ("displacement_opening_mm", "displacement\nopening (mm)"), ("stiffness_opening_per_s", "stiffness\nopening (1/s)"),
           ("lip_aperture_mm", "lip aperture\n(mm)"), ("lip_protrusion_mm", "lip protrusion\n(mm)"),
           ("jaw_opening_mm", "jaw opening\n(mm)"), ("gesture_duration_ms", "gesture\n(ms)"),
           ("epg_percent_contact", "EPG contact\nat closure (%)"), ("epg_cog", "EPG centre\nof gravity"),
           ("epg_anteriority", "EPG\nanteriority"), ("epg_posteriority", "EPG\nposteriority"))
PALATES = (("generic", "generic palate (placed by the rest sensors: an estimate)"), ("none", "no palate"))


def _cell(value, key: str = "") -> str:
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, str):
        return value or "–"
    if isinstance(value, int):
        return str(value)
    return "–" if not math.isfinite(value) else f"{value:.3f}" if key == "closure_s" else f"{value:.2f}"


class MeasuresTab(QtWidgets.QWidget):
    """The measures of the app model's primary session (``set_session`` for scripts)."""

    measured = QtCore.Signal(object)  # the MeasuresResult shown (None when there is none)

    def __init__(self, state=None, parent=None):
        super().__init__(parent)
        self.state = state
        self.session = None
        self.result = None
        self._key = None
        self.worker = None  # the running measurement's Job
        self._figure_stale = False
        self.palate_box = QtWidgets.QComboBox()
        self.palate_box.setSizeAdjustPolicy(QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        self.palate_box.setMinimumContentsLength(24)
        self.palate_box.currentIndexChanged.connect(lambda _i: self.refresh())
        self.save_button = QtWidgets.QPushButton("Save table…")
        self.save_button.clicked.connect(self.ask_save)
        self.table = QtWidgets.QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels([header for _, header in COLUMNS])
        self.table.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QtWidgets.QAbstractItemView.SelectionMode.ExtendedSelection)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.verticalHeader().setVisible(False)
        self.table.horizontalHeader().setDefaultSectionSize(84)
        self.table.itemSelectionChanged.connect(self._show_repetitions)
        self.table.cellDoubleClicked.connect(self._seek)
        self.sti_label = QtWidgets.QLabel()
        self.sti_label.setWordWrap(True)
        self.status = QtWidgets.QLabel("open a recording")
        self.status.setWordWrap(True)
        self.canvas = FigureCanvasQTAgg(Figure(figsize=(6, 2.6), layout="constrained"))
        self.canvas.setMinimumHeight(180)
        top = QtWidgets.QHBoxLayout()
        top.addWidget(QtWidgets.QLabel("palate"))
        top.addWidget(self.palate_box, 1)
        top.addWidget(self.save_button)
        split = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        split.addWidget(self.table)
        below = QtWidgets.QWidget()
        below_layout = QtWidgets.QVBoxLayout(below)
        below_layout.setContentsMargins(0, 0, 0, 0)
        below_layout.addWidget(self.sti_label)
        below_layout.addWidget(self.canvas, 1)
        split.addWidget(below)
        split.setSizes([200, 260])
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(split, 1)
        layout.addWidget(self.status)
        self._fill_palates()
        self._subscriptions = []
        if state is not None:
            self._subscriptions = [
                state.follow_session(self.set_session),
                connected(state.events.productions, lambda e: e.key == "primary" and self.set_session(e.value)),
                connected(state.events.run_settings, lambda _e: self._fill_palates()),
            ]
            if state.session is not None:
                self.set_session(state.session)
        app = QtWidgets.QApplication.instance()
        if app is not None:
            app.aboutToQuit.connect(self.stop_worker)

    # ------------------------------------------------------------------ inputs
    def _fill_palates(self) -> None:
        """The palate choices: the run's speaker palate first (chosen) when it has one, then generic and none."""
        from tonguevis.render.drawing import palate_label

        speaker = getattr(getattr(self.state, "run_settings", None), "palate", None)
        items = list(PALATES)
        if speaker is not None and str(speaker) != "generic" and not getattr(speaker, "metadata", {}).get("generic"):
            items.insert(0, (speaker, palate_label(speaker)))
        current = self.palate_box.currentData()
        self.palate_box.blockSignals(True)
        self.palate_box.clear()
        for data, text in items:
            self.palate_box.addItem(text, data)
        same = (lambda data: data == current) if isinstance(current, str) else (lambda data: data is current)
        index = next((i for i, (data, _) in enumerate(items) if same(data)), 0) if current is not None else 0
        self.palate_box.setCurrentIndex(index)
        self.palate_box.blockSignals(False)
        self.refresh()

    def set_session(self, session) -> None:
        """Measure ``session`` (the app model calls it when a recording opens or its productions change)."""
        self.session = session
        self.refresh()

    def refresh(self) -> None:
        """Recompute the measures when the recording, its productions or the palate changed: in the job
        runner (a long recording takes seconds: rest, head correction, the palate's placement), the
        result shown when it is still the one asked for."""
        session = self.session
        table = None if session is None else getattr(session, "production_table", None)
        chosen = self.palate_box.currentData()  # a str comes back as a new object each time: compared by value
        key = (id(session), id(table), len(table) if table is not None else 0,
               chosen if isinstance(chosen, str) or chosen is None else id(chosen))
        if key == self._key:
            self._add_palatograms()  # the simulation finished since: its palatograms join the rows
            return
        self._key = key
        self.result = None
        if self.worker is not None and self.worker.isRunning():
            self.worker.cancel()  # its result would be stale
        if session is None or table is None or not len(table):
            self._show_rows([])
            self.status.setText("open a recording with productions" if session is None or table is None
                                else "no productions in this recording")
            self.measured.emit(None)
            return
        from tonguevis.gui.worker import JobReactions, run_job
        from tonguevis.workflows.measures import measure_table, measurement_palate

        recording, spec, rest = session.recording, self.palate_box.currentData(), getattr(session, "given_rest", None)

        def work(progress):
            progress(0, 2, "placing the palate")
            palate = measurement_palate(recording, spec)
            progress(1, 2, f"measuring {len(table)} productions")
            return measure_table(recording, table, palate, rest=rest)

        self.status.setText("measuring…")
        self.worker = run_job(self, "Measures", work, lambda result: self._on_measured(result, key),
                              JobReactions(on_failed=lambda message: self._on_failed(message, key)),
                              label="Measuring the productions…", min_duration_ms=500)

    def _on_measured(self, result, key) -> None:
        if key != self._key:  # another recording, productions or palate since
            return
        session = self.session
        self.result = result
        self._epg_of = None
        self._add_palatograms(show=False)
        self._show_rows(result.rows)
        notes = result.notes + ([result.rest.describe()] if result.rest is not None else [])
        self.status.setText(f"{session.name}: {len(result.rows)} productions; head-corrected mm; speeds of the 12 Hz "
                            "low-passed sensor. " + " ".join(f"{n}." if not n.endswith(".") else n for n in notes))
        self.measured.emit(result)

    def _add_palatograms(self, show: bool = True) -> None:
        """Each production's palatogram at its closure (:func:`tonguevis.analysis.epg.production_epg`) into the
        rows, once the session's motion was simulated against a palate: the simulated tongue beside the sensors'
        measures (a fraction of a second: the few frames around each closure)."""
        motion = getattr(self.session, "motion", None)
        table = getattr(self.session, "production_table", None)
        if (self.result is None or motion is None or getattr(motion, "palate", None) is None or table is None
                or len(self.result.rows) != len(table) or getattr(self, "_epg_of", None) is motion):
            return
        from tonguevis.analysis.epg import production_epg

        for row, epg in zip(self.result.rows, production_epg(motion, table)):
            row.update(epg)
        self._epg_of = motion
        if show:
            self._show_rows(self.result.rows)

    def _on_failed(self, message: str, key) -> None:
        if key != self._key:
            return
        logger.warning("measures: %s", message)
        self._show_rows([])
        self.status.setText(f"cannot measure: {message}")
        self.measured.emit(None)

    def stop_worker(self) -> None:
        """Cancel a running measurement and wait for its thread (before closing)."""
        if self.worker is not None:
            self.worker.stop()

    # ------------------------------------------------------------------ showing
    def _show_rows(self, rows: list[dict]) -> None:
        self.table.blockSignals(True)
        self.table.clearContents()
        self.table.setRowCount(len(rows))
        for r, row in enumerate(rows):
            for c, (key, _) in enumerate(COLUMNS):
                item = QtWidgets.QTableWidgetItem(_cell(row.get(key), key))
                if c >= 3:
                    item.setTextAlignment(QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter)
                if key == "constriction_degree_mm" and row.get("constriction_at_palate_edge"):
                    item.setToolTip("beyond the palate's extent: the distance is to its edge")
                self.table.setItem(r, c, item)
        self.table.blockSignals(False)
        self.table.resizeColumnsToContents()
        self._show_repetitions()

    def selected_rows(self) -> list[int]:
        """The selected productions (indices of the table's rows), all of them when none is selected."""
        chosen = sorted({index.row() for index in self.table.selectionModel().selectedRows()})
        return chosen or list(range(self.table.rowCount()))

    def selected_repetitions(self):
        """The :class:`~tonguevis.analysis.repetitions.Repetitions` of the selected productions, or None."""
        if self.result is None or not self.result.rows:
            return None
        return self.result.repetitions.subset(self.selected_rows())

    def _show_repetitions(self) -> None:
        from tonguevis.render.repetitions import draw_averages

        reps = self.selected_repetitions()
        if reps is None:
            self.sti_label.setText("")
            self.canvas.figure.clear()
            self.canvas.draw_idle()
            return
        every = len(self.selected_rows()) == self.table.rowCount()
        values = ", ".join(f"{n} {v:.2f}" if math.isfinite(v) else f"{n} –" for n, v in reps.sti.items())
        which = "all" if every else "the selected"
        self.sti_label.setText(f"STI over {which} {reps.n} productions (Smith et al. 2000; vertical position, "
                               f"time- and amplitude-normalised): {values}"
                               + (" (select two or more for an STI)" if reps.n < 2 else ""))
        if not self.isVisible():  # drawn when the tab shows (a hidden canvas has no size to lay out)
            self._figure_stale = True
            return
        self._figure_stale = False
        draw_averages(self.canvas.figure, reps, columns=min(4, max(len(reps.sensors), 1)))
        self.canvas.draw_idle()

    def showEvent(self, event) -> None:
        super().showEvent(event)
        if self._figure_stale:
            self._show_repetitions()

    def _seek(self, row: int, _column: int) -> None:
        if self.result is None or self.state is None or not 0 <= row < len(self.result.rows):
            return
        closure = self.result.rows[row]["closure_s"]
        if math.isfinite(closure):
            self.state.set_time(float(closure), self)

    # ------------------------------------------------------------------ saving
    def ask_save(self) -> Path | None:
        """Save the table (CSV or Parquet) where the user says; returns the path written, or None."""
        from tonguevis.analysis.measures import write_measures

        if self.result is None:
            self.status.setText("nothing to save: open a recording with productions")
            return None
        default = f"{Path(self.session.name).stem}_measures.csv"
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Save the measures", default,
                                                        "CSV (*.csv);;Parquet (*.parquet)")
        if not path:
            return None
        try:
            written = write_measures(self.result.rows, path)
        except (TonguevisError, OSError) as exc:
            from tonguevis.gui.dialogs import error_box

            error_box(self, "Measures not saved", str(exc), path)
            return None
        self.status.setText(f"saved {written}")
        return Path(written)

    def closeEvent(self, event) -> None:
        for unsubscribe in self._subscriptions:
            unsubscribe()
        self._subscriptions = []
        self.stop_worker()
        super().closeEvent(event)
