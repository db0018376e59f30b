"""The Energy tab: overlaid energy-time curves of productions, grouped and filtered (§6.3, Fig. 14).

Shows :class:`~tonguevis.analysis.energy.EnergyCurve` objects (one per
production) coloured by group (speaker × syllable by default) with a legend.
Lists on the left choose the recordings, speakers and syllables shown.
Hovering a curve names its production; clicking a point selects that frame:
the tab emits :attr:`EnergyTab.frameSelected` (recording name, time in s on the
recording's clock) and, when the clicked recording is the one the app shows
(``current_recording``, by default the app model's primary session), moves the
shared :class:`~tonguevis.appstate.AppState` there so the 3D views follow.  The
picked frame can be sent to the Morph tab as its source or target: through the
app model (``state.set_morph_end``), and as :attr:`EnergyTab.morphEndPicked`.

With an app model the tab adds the curves of every recording the app simulates
(its ``motion`` events) and writes the motions of its curves back
(``state.add_motions``), where the Morph tab finds them.  "Add recordings…"
simulates more through the job runner, with a progress bar and Cancel.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np
from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure
from PySide6 import QtCore, QtWidgets


from tonguevis.analysis.energy import EnergyCurve
from tonguevis.render.energy import plot_energy_curves
from tonguevis.appstate import connected
from tonguevis.gui.flow_layout import FlowLayout

from tonguevis._logging import logger

UNIT_SCALE = 1e3  # the axis shows mJ


class EnergyTab(QtWidgets.QWidget):
    """Energy curves of many productions; ``set_curves`` fills it.

    state : the app model (optional); current_recording : callable returning the name
    of the recording the 3D views show (default: the stem of the model's primary session).
    model_provider : callable making the tongue model for "Add recordings…" (called in the
    job's thread; default: the app model's, else the one of the run settings, built by the job).
    settings : the :class:`~tonguevis.sim.settings.RunSettings` "Add recordings…" simulates with (default: the
    app model's ``run_settings`` at the time, so the curves are simulated as the views' recording is).
    """

    frameSelected = QtCore.Signal(str, float)
    morphEndPicked = QtCore.Signal(str, str, float)  # "source"/"target", recording, time (s)
    motionsLoaded = QtCore.Signal(dict)  # recording name -> Motion, after "Add recordings"

    def __init__(self, state=None, current_recording: Callable[[], str | None] | None = None, parent=None,
                 model_provider: Callable[[], object] | None = None, settings=None):
        super().__init__(parent)
        self.state = state
        self.current_recording = current_recording or self._shown_recording
        self.model_provider = model_provider
        self.settings = settings
        self.motions: dict = {}
        self.job = None
        self.curves: list[EnergyCurve] = []
        self.lines: list = []  # matplotlib Line2D per shown curve
        self.shown: list[EnergyCurve] = []
        self.picked: tuple[EnergyCurve, int] | None = None

        self.recordings = self._list("Recordings")
        self.speakers = self._list("Speakers")
        self.syllables = self._list("Syllables")
        self.normalised = QtWidgets.QCheckBox("normalised time")
        self.normalised.setToolTip("0 = the consonant release, 1 = the next release; unticked: seconds")
        self.normalised.setChecked(True)
        self.normalised.toggled.connect(self.redraw)
        self.group_by = QtWidgets.QComboBox()
        for text, keys in (("speaker × syllable", ("speaker", "syllable")), ("speaker", ("speaker",)),
                           ("syllable", ("syllable",)), ("recording", ("recording",))):
            self.group_by.addItem(text, keys)
        self.group_by.currentIndexChanged.connect(self.redraw)

        self.figure = Figure(figsize=(6, 4), layout="constrained")
        self.canvas = FigureCanvasQTAgg(self.figure)
        self.axes = self.figure.add_subplot(1, 1, 1)
        self.marker = None
        self.hover_label = QtWidgets.QLabel("Hover a curve to see its production; click to show that frame.")
        self.hover_label.setWordWrap(True)  # two lines in a narrow tab rather than a wider window
        self.pick_label = QtWidgets.QLabel("No frame picked.")
        self.to_source = QtWidgets.QPushButton("Morph source ←")
        self.to_target = QtWidgets.QPushButton("Morph target ←")
        for button, which in ((self.to_source, "source"), (self.to_target, "target")):
            button.setEnabled(False)
            button.setToolTip(f"use the picked frame as the morph's {which} (t = {0 if which == 'source' else 1})")
            button.clicked.connect(lambda _=False, w=which: self._send_morph_end(w))
        self.canvas.mpl_connect("motion_notify_event", self._on_motion)
        self.canvas.mpl_connect("button_press_event", self._on_click)

        self.add_button = QtWidgets.QPushButton("Add recordings…")
        self.add_button.setToolTip("simulate recordings or folders of recordings and add their production curves")
        self.add_button.clicked.connect(self._ask_paths)
        self.progress = QtWidgets.QProgressBar()
        self.progress.setVisible(False)
        self.cancel_button = QtWidgets.QPushButton("Cancel")
        self.cancel_button.setToolTip("stop adding recordings (those simulated so far are dropped)")
        self.cancel_button.setVisible(False)
        self.cancel_button.clicked.connect(self.cancel)

        side = QtWidgets.QVBoxLayout()
        side.addWidget(self.add_button)
        side.addWidget(self.progress)
        side.addWidget(self.cancel_button)
        for title, widget in (("Recordings", self.recordings), ("Speakers", self.speakers),
                              ("Syllables", self.syllables)):
            side.addWidget(QtWidgets.QLabel(title))
            side.addWidget(widget)
        side.addWidget(self.normalised)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("colour by"))
        row.addWidget(self.group_by)
        side.addLayout(row)
        main = QtWidgets.QVBoxLayout()
        self.frame_label = QtWidgets.QLabel("Elastic energy of the tongue's deformation, in the jaw frame (the jaw's "
                                            "motion removed: moving with the jaw costs no energy).")
        self.frame_label.setWordWrap(True)
        main.addWidget(self.frame_label)
        main.addWidget(self.canvas, 1)
        main.addWidget(self.hover_label)
        picks = FlowLayout()  # wraps where the tab is narrow (1280 pixels beside the 3D views)
        picks.addWidget(self.pick_label)
        picks.addWidget(self.to_source)
        picks.addWidget(self.to_target)
        main.addLayout(picks)
        layout = QtWidgets.QHBoxLayout(self)
        side_widget = QtWidgets.QWidget()
        side_widget.setLayout(side)
        side_widget.setMaximumWidth(230)
        layout.addWidget(side_widget)
        layout.addLayout(main, 1)
        self.redraw()
        self._unsubscribe = connected(state.events.motion, self._on_simulated) if state is not None else None

    def _shown_recording(self) -> str | None:
        session = None if self.state is None else self.state.session
        return None if session is None or session.path is None else session.path.stem

    def _on_simulated(self, event) -> None:
        """A recording of the app was simulated: add its production curves."""
        session = event.value
        if session.motion is None or session.production_table is None or "preview" in session.motion.metadata:
            return  # a long recording's first seconds: its curves come with the whole motion
        try:
            self.add_motion(session.name, session.motion, session.production_table)
        except Exception as exc:  # the main views must not suffer from a tab's problem
            logger.warning("energy curves of %s not added: %s", session.name, exc)

    def _list(self, title: str) -> QtWidgets.QListWidget:
        widget = QtWidgets.QListWidget()
        widget.setToolTip(f"{title}: tick the ones to show")
        widget.setObjectName(title.lower())
        widget.itemChanged.connect(lambda _item: self.redraw())
        return widget

    # ------------------------------------------------------------------ data
    def set_curves(self, curves: Sequence[EnergyCurve]) -> None:
        """Show these curves (all ticked); replaces what was there."""
        self.curves = list(curves)
        for widget, key in ((self.recordings, "recording"), (self.speakers, "speaker"), (self.syllables, "syllable")):
            widget.blockSignals(True)
            widget.clear()
            for value in sorted({str(getattr(c, key)) for c in self.curves}):
                item = QtWidgets.QListWidgetItem(f"/{value}/" if key == "syllable" else value)
                item.setData(QtCore.Qt.UserRole, value)
                item.setFlags(item.flags() | QtCore.Qt.ItemIsUserCheckable)
                item.setCheckState(QtCore.Qt.Checked)
                widget.addItem(item)
            widget.blockSignals(False)
        self.picked = None
        self.redraw()

    def add_curves(self, curves: Sequence[EnergyCurve], motions: dict | None = None) -> None:
        """Add curves (replacing earlier ones of the same recordings) and their motions."""
        names = {c.recording for c in curves}
        self.set_curves([c for c in self.curves if c.recording not in names] + list(curves))
        if motions:
            self.motions.update(motions)
            if self.state is not None:
                self.state.add_motions(motions, source=self)
            self.motionsLoaded.emit(dict(self.motions))

    def add_motion(self, name: str, motion, productions) -> None:
        """Add the curves of a motion the app simulated itself (``name``: its file name or stem;
        speaker and syllable parsed from it, see :mod:`tonguevis.analysis.corpus`)."""
        from pathlib import Path

        from tonguevis.analysis.corpus import labels_from_name
        from tonguevis.analysis.energy import production_curves

        entry = labels_from_name(Path(name))
        stem = entry.name
        curves = production_curves(motion, productions, recording=stem, speaker=entry.speaker,
                                   syllable=entry.syllable, trial=entry.trial)
        self.add_curves(curves, {stem: motion})

    # ------------------------------------------------------------------ loading in the background
    def _ask_paths(self) -> None:
        files, _ = QtWidgets.QFileDialog.getOpenFileNames(self, "Recordings to add")
        if files:
            self.load_paths(files)

    def run_settings(self):
        """The :class:`~tonguevis.sim.settings.RunSettings` the recordings added are simulated with."""
        from tonguevis.sim.settings import RunSettings

        if self.settings is not None:
            return self.settings
        return self.state.run_settings if self.state is not None else RunSettings()

    def load_paths(self, paths) -> None:
        """Simulate the recordings (files or folders) through the job runner, then add their curves."""
        from tonguevis.analysis.corpus import load_corpus
        from tonguevis.workflows.corpus import corpus_energy_curves
        from tonguevis.errors import TonguevisError
        from tonguevis.gui.worker import JobReactions, run_job

        if self.job is not None and self.job.isRunning():
            return
        try:
            corpus = load_corpus(paths)
        except (TonguevisError, OSError) as exc:
            self.hover_label.setText(f"Cannot add: {exc}")
            return
        # Read on the GUI thread; a model the job has to build is handed back, not assigned there.
        model = None if self.state is None else self.state.tongue_model
        mesh_path = None if self.state is None else self.state.mesh_path
        provider, settings = self.model_provider, self.run_settings()

        def work(progress):
            from tonguevis.sim.settings import build_model

            used = model
            if used is None:
                used = provider() if provider is not None else build_model(settings)
            return corpus_energy_curves(corpus, settings, used, progress=progress), used

        self.add_button.setEnabled(False)
        self.progress.setVisible(True)
        self.cancel_button.setVisible(True)
        self.job = run_job(self, "Add recordings", work, lambda done: self._on_loaded(*done, mesh_path),
                           JobReactions(on_failed=lambda message: self._finish(f"Cannot add: {message}"),
                                        on_cancelled=lambda: self._finish("Adding recordings cancelled.")),
                           dialog=False)
        self.job.progressed.connect(self._on_progress)

    def cancel(self) -> None:
        if self.job is not None:
            self.job.cancel()

    def _on_progress(self, done: int, total: int, message: str) -> None:
        self.progress.setRange(0, max(total, 1))
        self.progress.setValue(done)
        self.progress.setFormat(message)

    def _on_loaded(self, result, model, mesh_path) -> None:
        if (self.state is not None and self.model_provider is None and self.state.tongue_model is None
                and self.state.mesh_path == mesh_path):
            self.state.set_tongue_model(model, mesh_path, self)  # built by the job: the app's from now on
        self.add_curves(result.curves, result.motions)
        self._finish(f"Added {len(result.curves)} production curves from {len(result.motions)} recording(s).")

    def _finish(self, message: str) -> None:
        self.add_button.setEnabled(True)
        self.progress.setVisible(False)
        self.cancel_button.setVisible(False)
        self.hover_label.setText(message)

    def closeEvent(self, event) -> None:  # noqa: N802 (Qt name)
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        if self.job is not None:
            self.job.stop(60_000)
        super().closeEvent(event)

    def ticked(self, widget: QtWidgets.QListWidget) -> set[str]:
        return {widget.item(i).data(QtCore.Qt.UserRole) for i in range(widget.count())
                if widget.item(i).checkState() == QtCore.Qt.Checked}

    def set_ticked(self, widget: QtWidgets.QListWidget, values) -> None:
        """Tick exactly ``values`` in a list (for scripts and tests)."""
        widget.blockSignals(True)
        for i in range(widget.count()):
            item = widget.item(i)
            item.setCheckState(QtCore.Qt.Checked if item.data(QtCore.Qt.UserRole) in values else QtCore.Qt.Unchecked)
        widget.blockSignals(False)
        self.redraw()

    def visible_curves(self) -> list[EnergyCurve]:
        recs, spks, syls = self.ticked(self.recordings), self.ticked(self.speakers), self.ticked(self.syllables)
        return [c for c in self.curves if c.recording in recs and c.speaker in spks and c.syllable in syls]

    # ------------------------------------------------------------------ drawing
    def redraw(self, *_args) -> None:
        ax = self.axes
        ax.clear()
        self.shown = self.visible_curves()
        plot_energy_curves(ax, self.shown, by=self.group_by.currentData(), normalised=self.normalised.isChecked())
        self.lines = list(ax.get_lines())
        if not self.shown:
            ax.text(0.5, 0.5, "no curves: add recordings or tick some", ha="center", va="center",
                    transform=ax.transAxes, color="0.4")
        self.marker = ax.plot([], [], "o", ms=9, mfc="none", mec="k", mew=1.5)[0]
        self._draw_pick()
        self.canvas.draw_idle()

    def _x(self, curve: EnergyCurve) -> np.ndarray:
        return curve.time_norm if self.normalised.isChecked() else curve.time_s

    def curve_at(self, xdata: float, ydata: float, tolerance_px: float = 6.0) -> tuple[EnergyCurve, int] | None:
        """The shown curve and frame nearest a data point, within ``tolerance_px`` pixels, else None."""
        if not self.shown or xdata is None or ydata is None:
            return None
        to_px = self.axes.transData.transform
        target = to_px((xdata, ydata))
        best, best_d = None, tolerance_px
        for curve in self.shown:
            pts = to_px(np.column_stack([self._x(curve), curve.energy * UNIT_SCALE]))
            d = np.hypot(pts[:, 0] - target[0], pts[:, 1] - target[1])
            k = int(np.argmin(d))
            if d[k] <= best_d:
                best, best_d = (curve, k), d[k]
        return best

    @staticmethod
    def describe(curve: EnergyCurve, k: int) -> str:
        return (f"{curve.speaker} /{curve.syllable}/ trial {curve.trial}, production {curve.production} "
                f"({curve.recording}): t = {curve.times[k]:.3f} s ({curve.time_s[k] * 1e3:.0f} ms after the "
                f"release, {curve.time_norm[k]:.2f} normalised), U = {curve.energy[k] * 1e3:.4f} mJ")

    def _on_motion(self, event) -> None:
        hit = self.curve_at(event.xdata, event.ydata) if event.inaxes is self.axes else None
        self.hover_label.setText(self.describe(*hit) if hit else "")

    def _on_click(self, event) -> None:
        if event.inaxes is not self.axes:
            return
        hit = self.curve_at(event.xdata, event.ydata)
        if hit:
            self.pick(*hit)

    def pick(self, curve: EnergyCurve, k: int) -> None:
        """Select frame ``k`` of ``curve``: mark it, emit frameSelected, move the app's time if it is shown."""
        self.picked = (curve, k)
        self._draw_pick()
        self.canvas.draw_idle()
        t = float(curve.times[k])
        self.pick_label.setText("Picked: " + self.describe(curve, k))
        self.to_source.setEnabled(True)
        self.to_target.setEnabled(True)
        self.frameSelected.emit(curve.recording, t)
        if self.state is not None and self.current_recording() == curve.recording:
            self.state.set_time(t, source=self)

    def _draw_pick(self) -> None:
        if self.marker is None:
            return
        if self.picked and self.picked[0] in self.shown:
            curve, k = self.picked
            self.marker.set_data([self._x(curve)[k]], [curve.energy[k] * UNIT_SCALE])
        else:
            self.marker.set_data([], [])

    def _send_morph_end(self, which: str) -> None:
        if self.picked:
            curve, k = self.picked
            if self.state is not None:
                self.state.set_morph_end(which, curve.recording, float(curve.times[k]), source=self)
            self.morphEndPicked.emit(which, curve.recording, float(curve.times[k]))

