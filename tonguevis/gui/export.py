"""Window exports: whole-window PNG, and the dialogs of the MP4, VTK and ParaView exports.

The exports run through the job runner (:func:`tonguevis.gui.worker.run_job`); each ``ask_*``
returns the job it started (None when the user cancelled a dialog) for the window to keep."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QPoint, Qt
from PySide6.QtGui import QImage, QPainter
from PySide6.QtWidgets import QComboBox, QDialog, QDialogButtonBox, QDoubleSpinBox, QFileDialog, QFormLayout

from tonguevis.appstate import interval_at
from tonguevis.errors import TonguevisError


def grab_window(window) -> QImage:
    """The whole window as an image, with the OpenGL 3D views painted in.

    ``QWidget.grab`` cannot read a native OpenGL surface (it comes out black
    on many platforms), so the 3D area is taken from VTK's own frame buffer
    and painted over its place in the window.
    """
    image = window.grab().toImage().convertToFormat(QImage.Format.Format_RGB888)
    interactor = window.view3d.plotter.interactor
    if interactor.isVisible():
        window.view3d.plotter.render()
        rgb = window.view3d.plotter.screenshot(None, return_img=True)
        h, w = rgb.shape[:2]
        vtk_image = QImage(rgb.tobytes(), w, h, 3 * w, QImage.Format.Format_RGB888).copy()
        where = interactor.mapTo(window, QPoint(0, 0))
        ratio = window.devicePixelRatioF() or 1.0
        painter = QPainter(image)
        target = vtk_image.scaled(int(interactor.width() * ratio), int(interactor.height() * ratio),
                                  Qt.AspectRatioMode.IgnoreAspectRatio, Qt.TransformationMode.SmoothTransformation)
        painter.drawImage(int(where.x() * ratio), int(where.y() * ratio), target)
        painter.end()
    return image


def atomic_save_image(image: QImage, path) -> None:
    """Save ``image`` as a PNG at ``path`` (a temporary file, then a rename)."""
    from tonguevis._files import atomic_write

    def write(tmp: Path) -> None:
        if not image.save(str(tmp), "PNG"):
            raise OSError(f"could not write {path}")

    atomic_write(path, write)


class RangeDialog(QDialog):
    """Start and end time of a video (defaults: the production under the cursor), and its frame
    of reference (default: the views')."""

    def __init__(self, state, productions, parent=None):
        from tonguevis.appstate import REFERENCE_FRAMES
        from tonguevis.gui.view3d import REFERENCE_LABELS

        super().__init__(parent)
        self.setWindowTitle("Video time range")
        default = interval_at(productions, state.time) or (state.start, state.end)
        self.start, self.end = QDoubleSpinBox(), QDoubleSpinBox()
        for box, value in ((self.start, default[0]), (self.end, default[1])):
            box.setDecimals(2)
            box.setRange(state.start, state.end)
            box.setSuffix(" s")
            box.setValue(value)
        self.frame = QComboBox()
        for frame in REFERENCE_FRAMES:
            self.frame.addItem(REFERENCE_LABELS[frame], frame)
        self.frame.setCurrentIndex(REFERENCE_FRAMES.index(state.reference))
        form = QFormLayout(self)
        form.addRow("from", self.start)
        form.addRow("to", self.end)
        form.addRow("frame", self.frame)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        form.addRow(buttons)


def run_with_progress(window, title: str, function, done_message: str, path, on_success=None):
    """Run ``function(progress=...)`` through the job runner (progress dialog, Cancel, errors as a
    dialog naming ``path``); ``done_message`` goes to the status line and ``on_success(result)`` is
    called on the GUI thread when it finished.  Returns the :class:`~tonguevis.gui.worker.Job`."""
    from tonguevis.gui.worker import JobReactions, run_job

    def done(result) -> None:
        window.state.set_status(done_message, window)
        if on_success is not None:
            on_success(result)

    return run_job(window, title, function, done,
                   JobReactions(path=path, status=lambda text: window.state.set_status(text, window)),
                   min_duration_ms=200)


def ask_video(window):
    from tonguevis.render.video import export_video

    session = window.session
    if session is None or session.frames is None:
        window.show_error("Nothing to export", "open a recording and let its simulation finish first")
        return
    ranges = RangeDialog(window.state, session.productions, window)
    if ranges.exec() != QDialog.DialogCode.Accepted:
        return
    path, _ = QFileDialog.getSaveFileName(window, "Save the video", f"{Path(session.name).stem}.mp4", "MP4 (*.mp4)")
    if not path:
        return
    start, end, mode = ranges.start.value(), ranges.end.value(), window.state.color
    frame = ranges.frame.currentData()
    return run_with_progress(window, "Video export",
                      lambda progress: export_video(session, path, start, end, mode=mode, progress=progress,
                                                    frame=frame),
                      f"saved {path} ({frame} frame)", path)


def ask_vtk(window):
    from tonguevis.render.video import export_vtk_series

    session = window.session
    if session is None or session.frames is None:
        window.show_error("Nothing to export", "open a recording and let its simulation finish first")
        return
    frame = window.state.reference  # what the views show (View ▸ Head frame / Jaw frame)
    folder = QFileDialog.getExistingDirectory(window, f"Folder for the VTK series ({frame} frame, as the views)")
    if folder:
        return run_with_progress(window, "VTK export",
                          lambda progress: export_vtk_series(session, folder, progress=progress, frame=frame),
                          f"saved {folder}/motion.pvd in the {frame} frame (README.txt there says so)", folder)


class ParaViewDialog(QDialog):
    """Options of the ParaView export: the surface only, every n-th frame."""

    def __init__(self, n_frames: int, parent=None):
        from PySide6.QtWidgets import QCheckBox, QSpinBox

        super().__init__(parent)
        self.setWindowTitle("ParaView export (XDMF + HDF5)")
        self.surface = QCheckBox("surface triangles only (about 40 % of the bytes)")
        self.stride = QSpinBox()
        self.stride.setRange(1, max(1, n_frames))
        self.stride.setPrefix("every ")
        self.stride.setSuffix(" frame(s)")
        form = QFormLayout(self)
        form.addRow(self.surface)
        form.addRow("frames", self.stride)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        form.addRow(buttons)


def ask_paraview(window):
    """File ▸ Export motion for ParaView: one .xdmf + .h5 (the mesh once, displacement and energy
    density per frame), in the frame of reference the views show.  Returns the export's job, or None."""
    from tonguevis.render.paraview import export_paraview

    session = window.session
    if session is None or session.motion is None:
        window.show_error("Nothing to export", "open a recording and let its simulation finish first")
        return
    options = ParaViewDialog(session.motion.n_frames, window)
    if options.exec() != QDialog.DialogCode.Accepted:
        return
    path, _ = QFileDialog.getSaveFileName(window, "Save the motion for ParaView", f"{Path(session.name).stem}.xdmf",
                                          "XDMF (*.xdmf)")
    if not path:
        return
    frame = getattr(window.state, "reference", "head")
    surface, stride = options.surface.isChecked(), options.stride.value()
    return run_with_progress(window, "ParaView export",
                      lambda progress: export_paraview(session, path, frame=frame, surface_only=surface,
                                                       stride=stride, progress=progress),
                      f"saved {path} and its .h5 ({frame} frame)", path)


def ask_productions(window, key: str):
    """File ▸ Export ▸ Productions (CSV) or (TextGrid): the primary recording's productions as they are
    now (corrected ones included) into a file the user names; EMA for Praat (``wav``): its sound and
    sensors.  Returns the path written, or None."""
    from tonguevis.workflows.exports import export_format, write_export

    fmt = export_format(key)
    session = window.session
    if session is None or (key != "wav" and getattr(session, "production_table", None) is None):
        window.show_error("Nothing to export", "open a recording with productions first" if session is not None
                          else "open a recording first")
        return None
    default = f"{Path(session.name).stem}{'_ema' if key == 'wav' else '_productions'}{fmt.suffix}"
    path, _ = QFileDialog.getSaveFileName(window, f"Save the {fmt.title}", default, f"{fmt.title} (*{fmt.suffix})")
    if not path:
        return None
    try:
        written = write_export(key, session, path)
    except (TonguevisError, OSError) as exc:
        window.show_error(f"{fmt.title} not saved", str(exc), path)
        return None
    window.state.set_status(f"saved {written}", window)
    return written


__all__ = ["TonguevisError", "ask_paraview", "ask_productions", "ask_video", "ask_vtk", "atomic_save_image",
           "grab_window"]
