"""The Segmentation tab: segment the tongue by how well local rigid or constraint modes fit (§5).

Choose the target (the frame under the cursor, the peak-energy frame of the
production under the cursor, or that whole production weighted by energy),
the mode, and the seeds (automatic, until the relative global error falls
under a threshold or a partition count is reached; or picked by clicking the
left view), then Run: the job runs in a worker thread behind a progress dialog
with Cancel.  Left: the target shape; right: the approximation, drawn from the
approximated displacement of each partition's own node copies, so rigid
pieces show gaps at their interfaces and constraint modes close them.  Both
are coloured by partition, or by the local error sqrt(e_E) in mm.
"""

from __future__ import annotations

import logging

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from tonguevis.errors import TonguevisError
from tonguevis.gui.segmentation_view import (ERROR_FIELD, TARGETS, approximation_surface, make_target,
                                             partition_table, target_surface)

log = logging.getLogger("tonguevis")
#: Direction from the tongue to the camera: its right side, a little in front and above.
VIEW = (0.45, -1.0, 0.5)


class SegmentationTab(QtWidgets.QWidget):
    """Segment the session's simulated motion; ``set_session`` is called by the window."""

    segmented = QtCore.Signal(object)  # the SegmentationResult shown
    finished = QtCore.Signal(str)  # "ok", "failed" or "cancelled"

    def __init__(self, state=None, parent=None):
        super().__init__(parent)
        self.state = state
        self.session = None
        self.result = None
        self.seeds: list[int] = []
        self.worker = None
        self.progress_dialog = None
        self.last_dialog = None
        self.plotter = None
        self.surfaces: dict = {}
        self._pick_observer = None

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
        self.colour_box.currentIndexChanged.connect(lambda _i: self._draw())
        self.table = QtWidgets.QPlainTextEdit()
        self.table.setReadOnly(True)
        self.table.setFont(QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont))
        self.table.setMaximumWidth(330)
        self.status = QtWidgets.QLabel("Choose a target, a mode and seeds, then press Run.")
        self.status.setWordWrap(True)

        form = QtWidgets.QGridLayout()
        form.addWidget(QtWidgets.QLabel("target"), 0, 0)
        form.addWidget(self.target_box, 0, 1, 1, 3)
        form.addWidget(QtWidgets.QLabel("mode"), 0, 4)
        form.addWidget(self.mode_box, 0, 5)
        form.addWidget(QtWidgets.QLabel("seeds"), 1, 0)
        form.addWidget(self.seeding_box, 1, 1)
        form.addWidget(self.threshold, 1, 2)
        form.addWidget(self.max_partitions, 1, 3)
        form.addWidget(self.pick_button, 1, 4)
        form.addWidget(self.clear_button, 1, 5)
        form.addWidget(self.seeds_label, 2, 1, 1, 5)
        form.addWidget(QtWidgets.QLabel("colour by"), 2, 6)
        form.addWidget(self.colour_box, 2, 7)
        form.addWidget(self.run_button, 0, 6, 2, 2)
        self.views_box = QtWidgets.QHBoxLayout()
        self.views_box.addWidget(self.table)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(form)
        layout.addLayout(self.views_box, 1)
        layout.addWidget(self.status)
        self.seeding_box.currentIndexChanged.connect(lambda _i: self._update_seeding())
        self._update_seeding()

    # ------------------------------------------------------------------ inputs
    def set_session(self, session) -> None:
        self.session = session

    def _update_seeding(self) -> None:
        auto = self.seeding_box.currentData() == "auto"
        self.threshold.setEnabled(auto)
        self.max_partitions.setEnabled(auto)
        shown = ", ".join(str(s) for s in self.seeds) if self.seeds else "none (turn on Pick seeds, click the left view)"
        self.seeds_label.setText(f"picked seed tets: {shown}")

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
            from pyvistaqt import QtInteractor

            self.plotter = QtInteractor(self, shape=(1, 2), border=False)
            self.plotter.set_background("white")
            self.plotter.link_views()
            self.views_box.addWidget(self.plotter.interactor, 1)
            self._draw()
        return self.plotter

    def showEvent(self, event) -> None:
        super().showEvent(event)
        self.ensure_views()

    def _draw(self) -> None:
        plotter, result = self.plotter, self.result
        if plotter is None:
            return
        plotter.clear()
        self.surfaces = {}
        if result is None:
            plotter.subplot(0, 0)
            plotter.add_text("target: run a segmentation", font_size=9, color="black")
            plotter.render()
            return
        by_error = self.colour_box.currentData() == "error"
        top = float(1000.0 * np.sqrt(result.element_errors.max())) or 1.0
        summary = (f"{result.mode} modes, {result.n_partitions} partitions, "
                   f"relative e_G {100 * result.relative_error:.2g} %")
        panels = [("target", target_surface(result), f"target: {result.metadata.get('description', '')}"),
                  ("approximation", approximation_surface(result), f"approximation: {summary}")]
        for column, (name, surface, caption) in enumerate(panels):
            plotter.subplot(0, column)
            if by_error:
                actor = plotter.add_mesh(surface, scalars=ERROR_FIELD, cmap="viridis", clim=(0.0, top),
                                         show_scalar_bar=column == 1,
                                         scalar_bar_args={"title": "local error (mm)", "color": "black",
                                                          "vertical": False, "position_x": 0.2, "width": 0.6})
            else:
                actor = plotter.add_mesh(surface, scalars="colour", rgb=True, lighting=True)
            plotter.add_text(caption, font_size=9, color="black", position="upper_left")
            self.surfaces[name], self.surfaces[f"{name}_actor"] = surface, actor
        plotter.subplot(0, 0)
        plotter.view_vector(VIEW, viewup=(0.0, 0.0, 1.0))
        plotter.reset_camera()
        plotter.camera.zoom(1.3)
        plotter.render()

    # ------------------------------------------------------------------ running
    def show_error(self, title: str, message: str) -> None:
        from tonguevis.gui.dialogs import error_box

        log.warning("%s: %s", title, message)
        self.status.setText(f"{title}: {message}")
        self.last_dialog = error_box(self, title, message)

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

        def function(progress):
            return segment(model, target, mode, progress=progress, **options)

        return function

    def run(self) -> None:
        from tonguevis.gui.worker import Worker

        if self.worker is not None and self.worker.isRunning():
            return
        try:
            function = self.job()
        except TonguevisError as exc:
            self.show_error("Cannot segment", str(exc))
            self.finished.emit("failed")
            return
        self.worker = Worker(function, self)
        dialog = QtWidgets.QProgressDialog("Segmenting…", "Cancel", 0, 1000, self)
        dialog.setWindowTitle("tonguevis: segmentation")
        dialog.setWindowModality(QtCore.Qt.WindowModality.WindowModal)
        dialog.setMinimumDuration(300)
        dialog.setValue(0)
        dialog.canceled.connect(self.worker.cancel)
        self.progress_dialog = dialog
        self.worker.progressed.connect(self._on_progress)
        self.worker.succeeded.connect(self._on_done)
        self.worker.failed.connect(self._on_failed)
        self.worker.cancelled.connect(self._on_cancelled)
        self.worker.finished.connect(dialog.reset)
        self.run_button.setEnabled(False)
        self.status.setText("segmenting…")
        self.worker.start()

    def cancel(self) -> None:
        if self.worker is not None:
            self.worker.cancel()

    def _on_progress(self, done: int, total: int, message: str) -> None:
        if self.progress_dialog is not None:
            self.progress_dialog.setMaximum(max(total, 1))
            self.progress_dialog.setValue(min(done, total))
            self.progress_dialog.setLabelText(message)

    def _on_done(self, result) -> None:
        self.run_button.setEnabled(True)
        self.show_result(result)
        self.finished.emit("ok")

    def _on_failed(self, message: str) -> None:
        self.run_button.setEnabled(True)
        self.show_error("Segmentation failed", message)
        self.finished.emit("failed")

    def _on_cancelled(self) -> None:
        self.run_button.setEnabled(True)
        self.status.setText("segmentation cancelled")
        self.finished.emit("cancelled")

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

    def closeEvent(self, event) -> None:
        if self.worker is not None and self.worker.isRunning():
            self.worker.cancel()
            self.worker.wait(30000)
        if self.plotter is not None:
            self.plotter.close()
        super().closeEvent(event)
