"""The Segmentation tab: segment the tongue by how well local rigid or constraint modes fit (§5).

Choose the target (the frame under the cursor, the peak-energy frame of the
production under the cursor, or that whole production weighted by energy),
the mode, and the seeds (automatic, until the relative global error falls
under a threshold or a partition count is reached; or picked by clicking the
left view), then Run: the job runs through the app's job runner, behind a progress
dialog with Cancel.  The tab follows the app model's primary session and time.  Left: the target shape; right: the approximation, drawn from the
approximated displacement of each partition's own node copies, so rigid
pieces show gaps at their interfaces and constraint modes close them.  Both
are coloured by partition, or by the local error sqrt(e_E) in mm.
"""

from __future__ import annotations


import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from tonguevis.errors import TonguevisError
from tonguevis.render.segmentation_view import (TARGETS, draw_frame, draw_result, draw_seed_markers, make_target,
                                             move_frame, partition_table)
from tonguevis.appstate import connected
from tonguevis.gui.flow_layout import FlowLayout

from tonguevis._logging import logger


class SegmentationTab(QtWidgets.QWidget):
    """Segment the simulated motion of the app model's primary session (``set_session`` for scripts)."""

    segmented = QtCore.Signal(object)  # the SegmentationResult shown
    finished = QtCore.Signal(str)  # "ok", "failed" or "cancelled", once the job's thread has ended

    def __init__(self, state=None, parent=None):
        super().__init__(parent)
        self.state = state
        self.session = None
        self.result = None
        self.seeds: list[int] = []
        self.worker = None  # the running segmentation's Job
        self.last_dialog = None
        self.plotter = None
        self.surfaces: dict = {}
        self._pick_observer = None
        self._running_motion = self._segmented_motion = None

        self.target_box = QtWidgets.QComboBox()
        for key, label in TARGETS.items():
            self.target_box.addItem(label, key)
        self.mode_box = QtWidgets.QComboBox()
        self.mode_box.addItem("rigid modes", "rigid")
        self.mode_box.addItem("constraint modes (continuous interfaces)", "constraint")
        self.seeding_box = QtWidgets.QComboBox()
        self.seeding_box.addItem("automatic", "auto")
        self.seeding_box.addItem("picked seeds", "picked")
        self.threshold = QtWidgets.QDoubleSpinBox()
        self.threshold.setRange(0.1, 99.0)
        self.threshold.setDecimals(1)
        self.threshold.setValue(5.0)
        self.threshold.setSuffix(" % e_G")
        self.threshold.setToolTip("automatic seeding stops once ‖ũ − u‖² / ‖u‖² is at most this")
        self.max_partitions = QtWidgets.QSpinBox()
        self.max_partitions.setRange(1, 64)
        self.max_partitions.setValue(12)
        self.max_partitions.setPrefix("max ")
        self.max_partitions.setSuffix(" partitions")
        self.pick_button = QtWidgets.QPushButton("Pick seeds")
        self.pick_button.setCheckable(True)
        self.pick_button.setToolTip("when on, clicking the left view adds the tet behind the clicked face as a seed")
        self.pick_button.toggled.connect(self._set_picking)
        self.clear_button = QtWidgets.QPushButton("Clear seeds")
        self.clear_button.clicked.connect(self.clear_seeds)
        self.seeds_label = QtWidgets.QLabel()
        self.run_button = QtWidgets.QPushButton("Run")
        self.run_button.clicked.connect(self.run)
        self.colour_box = QtWidgets.QComboBox()
        self.colour_box.addItem("partition", "partition")
        self.colour_box.addItem("local error sqrt(e_E), mm", "error")
        self.colour_box.setToolTip("the target (left) is always coloured by partition")
        self.colour_box.currentIndexChanged.connect(lambda _i: self._draw())
        self.scale_box = QtWidgets.QComboBox()
        for factor in (1, 2, 5, 10):
            self.scale_box.addItem(f"displacement ×{factor}", float(factor))
        self.scale_box.setToolTip("exaggerate the displacements of both shapes: rigid pieces' gaps become visible")
        self.scale_box.currentIndexChanged.connect(lambda _i: self.result is not None and self._draw())
        self.table = QtWidgets.QPlainTextEdit()
        self.table.setReadOnly(True)
        self.table.setFont(QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont))
        self.table.setMaximumWidth(290)
        self.status = QtWidgets.QLabel("Choose a target, a mode and seeds, then press Run.")
        self.status.setWordWrap(True)

        # Rows that wrap where the tab is narrow (1280 pixels beside the 3D views) instead of widening it.
        first, second, third = FlowLayout(), FlowLayout(), FlowLayout()
        for row, widgets in ((first, (QtWidgets.QLabel("target"), self.target_box, QtWidgets.QLabel("mode"),
                                      self.mode_box, self.run_button)),
                             (second, (QtWidgets.QLabel("seeds"), self.seeding_box, self.threshold,
                                       self.max_partitions, self.pick_button, self.clear_button)),
                             (third, (self.seeds_label, QtWidgets.QLabel("approximation coloured by"),
                                      self.colour_box, self.scale_box))):
            for widget in widgets:
                row.addWidget(widget)
        # Long item texts must not widen the whole window: the combos elide instead.
        for box in (self.target_box, self.mode_box, self.colour_box):
            box.setSizeAdjustPolicy(QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
            box.setMinimumContentsLength(14)
        self.seeds_label.setMinimumWidth(50)
        form = QtWidgets.QVBoxLayout()
        form.addLayout(first)
        form.addLayout(second)
        form.addLayout(third)
        self.views_box = QtWidgets.QHBoxLayout()
        self.views_box.addWidget(self.table)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(form)
        layout.addLayout(self.views_box, 1)
        layout.addWidget(self.status)
        self.seeding_box.currentIndexChanged.connect(lambda _i: self._update_seeding())
        self._update_seeding()
        self._subscriptions = []
        if state is not None:
            self._subscriptions = [connected(state.events.time, self._on_time), state.follow_session(self.set_session)]
            if state.session is not None:
                self.set_session(state.session)
        app = QtWidgets.QApplication.instance()
        if app is not None:
            app.aboutToQuit.connect(self.stop_worker)

    # ------------------------------------------------------------------ inputs
    def set_session(self, session) -> None:
        """The session shown (the app model calls it when a recording opens and when its simulation ends)."""
        motion = None if session is None else session.motion
        if motion is not self._segmented_motion:  # another recording, or re-simulated
            self.result, self._segmented_motion = None, None
            self.table.clear()
        self.session = session
        self._draw()

    def _update_seeding(self) -> None:
        auto = self.seeding_box.currentData() == "auto"
        self.threshold.setEnabled(auto)
        self.max_partitions.setEnabled(auto)
        shown = ", ".join(str(s) for s in self.seeds) if self.seeds else "none (turn on Pick seeds, click the left view)"
        self.seeds_label.setText(f"picked seed tets: {shown}")
        self._draw_seeds()

    def clear_seeds(self) -> None:
        self.seeds = []
        self._update_seeding()

    def pick_cell(self, cell_id: int) -> int | None:
        """Add the tet behind face ``cell_id`` of the left (target) view as a seed; returns it."""
        surface = self.surfaces.get("target")
        if surface is None or not 0 <= int(cell_id) < surface.n_cells:
            return None
        tet = int(surface.cell_data["tet"][int(cell_id)])
        if tet not in self.seeds:
            self.seeds.append(tet)
        self.seeding_box.setCurrentIndex(self.seeding_box.findData("picked"))
        self._update_seeding()
        return tet

    def _set_picking(self, on: bool) -> None:
        plotter = self.ensure_views()
        if self._pick_observer is not None:
            plotter.iren.remove_observer(self._pick_observer)
            self._pick_observer = None
        if on:
            self._pick_observer = plotter.iren.add_observer("LeftButtonPressEvent", self._on_click)

    def _on_click(self, *_args) -> None:
        import vtk

        surface_actor = self.surfaces.get("target_actor")
        if surface_actor is None:
            return
        x, y = self.plotter.iren.get_event_position()
        picker = vtk.vtkCellPicker()
        picker.SetTolerance(0.0005)
        picker.PickFromListOn()
        picker.AddPickList(surface_actor)
        if picker.Pick(x, y, 0, self.plotter.renderers[0]) and picker.GetCellId() >= 0:
            self.pick_cell(picker.GetCellId())
            self.status.setText(f"seed added: tet {self.seeds[-1]}; {len(self.seeds)} seed(s)")

    # ------------------------------------------------------------------ views
    def ensure_views(self):
        """The two side-by-side views, built on first need (the tab costs nothing until shown)."""
        if self.plotter is None:
            from tonguevis.gui.view3d import make_plotter

            self.plotter = make_plotter(self, shape=(1, 2), border=False)
            self.plotter.set_background("white")
            self.plotter.link_views()
            self.views_box.addWidget(self.plotter.interactor, 1)
            self._draw()
        return self.plotter

    def showEvent(self, event) -> None:
        super().showEvent(event)
        self.ensure_views()
        self._on_time()

    def _draw(self) -> None:
        plotter, result = self.plotter, self.result
        if plotter is None:
            return
        plotter.clear()
        self.surfaces = {}
        if result is not None:
            self.surfaces = draw_result(plotter, result, self.colour_box.currentData() == "error",
                                        float(self.scale_box.currentData()))
        else:
            motion = None if self.session is None else self.session.motion
            if motion is None:
                plotter.subplot(0, 0)
                plotter.add_text("no simulated motion yet", font_size=9, color="black")
            else:
                frame = motion.frame_at(self.current_time())
                self.surfaces = draw_frame(plotter, self._frame_points(motion, frame), motion.model.mesh.tets,
                                           float(motion.times[frame]))
        self._draw_seeds()

    @staticmethod
    def _frame_points(motion, frame: int) -> np.ndarray:
        return motion.model.mesh.points + motion.displacement(frame)

    def _on_time(self, _event=None) -> None:
        """Before any result the left view follows the cursor (points moved in place, one render)."""
        motion = None if self.session is None else self.session.motion
        surface = self.surfaces.get("target")
        if self.result is not None or motion is None or surface is None or not self.isVisible():
            return
        frame = motion.frame_at(self.current_time())
        move_frame(self.plotter, surface, self._frame_points(motion, frame), float(motion.times[frame]))
        self._draw_seeds()

    def _draw_seeds(self) -> None:
        """Black dots at the result's seed tets, red ones at the picked seeds (left view)."""
        plotter, surface = self.plotter, self.surfaces.get("target")
        if plotter is None or surface is None:
            return
        if self.result is not None:
            result, scale = self.result, float(self.scale_box.currentData())
            tets, points = result.tets, result.points + scale * result.target[result.peak_frame]
        else:
            motion = self.session.motion
            tets, points = motion.model.mesh.tets, self._frame_points(motion, motion.frame_at(self.current_time()))
        groups = {"picked seeds": (self.seeds, "red")}
        if self.result is not None:
            groups["result seeds"] = (self.result.seeds, "black")
        # Seeds inside the mesh are marked at their tet's centre (drawn over the surface).
        draw_seed_markers(plotter, points[tets].mean(axis=1), groups)
        plotter.render()

    # ------------------------------------------------------------------ running
    def show_error(self, title: str, message: str, path=None):
        from tonguevis.gui.dialogs import error_box

        logger.warning("%s: %s", title, message)
        self.status.setText(f"{title}: {message}")
        self.last_dialog = error_box(self, title, message, path)
        return self.last_dialog

    def current_time(self) -> float:
        return float(self.state.time) if self.state is not None else 0.0

    def job(self):
        """The segmentation to run, as ``function(progress=...)``; raises TonguevisError on bad input."""
        from tonguevis.analysis.segmentation import segment

        session = self.session
        motion = None if session is None else session.motion
        productions = [] if session is None else session.productions
        target = make_target(self.target_box.currentData(), motion, productions, self.current_time())
        mode = self.mode_box.currentData()
        if self.seeding_box.currentData() == "auto":
            options = {"seeds": "auto", "threshold": self.threshold.value() / 100.0,
                       "n_partitions": self.max_partitions.value()}
        else:
            if not self.seeds:
                raise TonguevisError("no seeds picked: turn on Pick seeds and click the left view, "
                                     "or choose automatic seeding")
            options = {"seeds": list(self.seeds)}
        model = motion.model
        self._running_motion = motion

        def function(progress):
            return segment(model, target, mode, progress=progress, **options)

        return function

    def run(self) -> None:
        from tonguevis.gui.worker import JobReactions, run_job

        if self.worker is not None and self.worker.isRunning():
            return
        try:
            function = self.job()
        except TonguevisError as exc:
            self.show_error("Cannot segment", str(exc))
            self.finished.emit("failed")
            return
        self.run_button.setEnabled(False)
        self.status.setText("segmenting…")
        self.worker = run_job(self, "Segmentation", function, self._on_done,
                              JobReactions(on_failed=lambda _message: self.run_button.setEnabled(True),
                                           on_cancelled=self._on_cancelled, on_ended=self.finished.emit),
                              label="Segmenting…")

    def cancel(self) -> None:
        if self.worker is not None:
            self.worker.cancel()

    def _on_done(self, result) -> None:
        self.run_button.setEnabled(True)
        current = None if self.session is None else self.session.motion
        if self._running_motion is not current:
            self.status.setText("segmentation of a motion no longer shown: discarded")
            return
        self._segmented_motion = current
        self.show_result(result)

    def _on_cancelled(self) -> None:
        self.run_button.setEnabled(True)
        self.status.setText("segmentation cancelled")

    def show_result(self, result) -> None:
        """Show a SegmentationResult: both views, the partition table, the status line."""
        self.result = result
        self.table.setPlainText(partition_table(result))
        seconds = result.metadata.get("seconds")
        self.status.setText(f"{result.metadata.get('description', 'target')}: {result.n_partitions} partitions, "
                            f"relative e_G {100 * result.relative_error:.2f} %"
                            + (f" ({seconds:.1f} s)" if seconds is not None else ""))
        if self.isVisible():
            self.ensure_views()
        self._draw()
        self.segmented.emit(result)

    def stop_worker(self) -> None:
        """Cancel a running segmentation and wait for its thread (before quitting)."""
        if self.worker is not None:
            self.worker.stop()

    def closeEvent(self, event) -> None:
        for unsubscribe in self._subscriptions:
            unsubscribe()
        self._subscriptions = []
        self.stop_worker()
        if self.plotter is not None:
            self.plotter.close()
        super().closeEvent(event)
