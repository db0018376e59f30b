"""The main window: 3D views, sensor panel and tabs, audio, transport, menus."""

from __future__ import annotations

import logging
import os
from pathlib import Path

from PySide6.QtCore import QSettings, Qt, Signal
from PySide6.QtWidgets import (QFileDialog, QLabel, QMainWindow, QProgressDialog, QSplitter, QTabWidget,
                               QVBoxLayout, QWidget)

from tonguevis.appstate import AppState
from tonguevis.errors import TonguevisError
from tonguevis.gui.audio_panel import AudioPlot
from tonguevis.gui.dialogs import SensorMapDialog, error_box
from tonguevis.gui.menus import MenusMixin
from tonguevis.gui.modal_tab import ModalTab
from tonguevis.gui.palate_actions import NO_PALATE, PalateMixin
from tonguevis.gui.palate_panel import PalatePanel
from tonguevis.gui.playback import PlaybackController
from tonguevis.gui.rest_dialog import RestMixin
from tonguevis.gui.sensor_panel import SensorPanel
from tonguevis.gui.session import Session, load_session, needs_sensor_map, remap_session
from tonguevis.gui.transport import TransportBar
from tonguevis.gui.view3d import View3D
from tonguevis.gui.worker import Worker

log = logging.getLogger("tonguevis")
MESH_SUFFIXES = (".vtu", ".vtk", ".msh", ".node", ".ele", ".mesh", ".npz", ".inp", ".xdmf")

#: Tabs other features add to every new window: (title, factory(state, window) -> QWidget).
TAB_FACTORIES: list[tuple[str, object]] = []


def register_tab_factory(title: str, factory) -> None:
    """Add a tab to every window created from now on (Energy, Morph, Segmentation ...).

    ``factory(state, window)`` returns the widget; if it has ``set_session(session)``
    it is called whenever a recording is opened or its simulation finishes.
    """
    TAB_FACTORIES.append((title, factory))


class MainWindow(MenusMixin, RestMixin, PalateMixin, QMainWindow):
    """The tonguevis window.  ``modes``, ``mesh_path`` and ``palate`` (None: no contact; "generic";
    a speaker's PalateSurface or palate file) configure the simulation."""

    session_changed = Signal(object)
    simulation_finished = Signal(bool)  # True on success

    def __init__(self, state: AppState | None = None, settings: QSettings | None = None, modes: int = 100,
                 mesh_path: str | os.PathLike | None = None, warping: bool = True, palate=None):
        super().__init__()
        self.setWindowTitle("tonguevis")
        self.resize(1500, 950)
        self.setAcceptDrops(True)
        self.state = state or AppState()
        self.settings = settings or QSettings("tonguevis", "tonguevis")
        self.modes, self.mesh_path, self.warping = modes, mesh_path, warping
        self.landmarks = "speaker"  # sensor nodes: the speaker's layout ("rule": the paper's placement)
        self.palate = palate
        self.session: Session | None = None
        self.model = None
        self.model_key = None
        self.worker: Worker | None = None
        self.progress_dialog: QProgressDialog | None = None
        self.last_dialog = None
        self.session_widgets: list = []
        self._build_views()
        self._build_menus()
        self.playback = PlaybackController(self.state, self)
        self.playback.status.connect(lambda text: self.statusBar().showMessage(text))
        self.statusBar().showMessage("Open a recording (File ▸ Open, or drop a file here)")
        self.frame_status = QLabel("")  # the views' frame of reference and the palate contact at the cursor
        self.frame_status.setStyleSheet("QLabel { border-left: 1px solid #b0b0b0; padding-left: 6px; }")
        self.frame_status.setToolTip("the 3D views' frame of reference (View ▸ Head frame / Jaw frame) and, at the "
                                     "cursor, the palate's penetration and contact area")
        self.statusBar().addPermanentWidget(self.frame_status)
        self.view3d.described.connect(self.frame_status.setText)
        self._build_rest_status()
        for title, factory in TAB_FACTORIES:
            self.register_tab(title, factory(self.state, self))

    # -- layout ---------------------------------------------------------------
    def _build_views(self) -> None:
        self.view3d = View3D(self.state, self)
        self.sensor_panel = SensorPanel(self.state, self)
        self.modal_tab = ModalTab(self.state, self)
        self.palate_panel = PalatePanel(self.state, self)
        self.tabs = QTabWidget()
        self.tabs.addTab(self.sensor_panel, "Sensors")
        self.tabs.addTab(self.modal_tab, "Modal q(t)")
        self.tabs.addTab(self.palate_panel, "Palate")
        self.audio = AudioPlot(self.state, self)
        self.transport = TransportBar(self.state, self)
        top = QSplitter(Qt.Orientation.Horizontal)
        top.addWidget(self.view3d)
        top.addWidget(self.tabs)
        top.setSizes([900, 600])
        vertical = QSplitter(Qt.Orientation.Vertical)
        vertical.addWidget(top)
        vertical.addWidget(self.audio)
        vertical.setSizes([720, 190])
        central = QWidget()
        layout = QVBoxLayout(central)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addWidget(vertical, 1)
        layout.addWidget(self.transport)
        self.setCentralWidget(central)
        self.session_widgets = [self.view3d, self.sensor_panel, self.modal_tab, self.palate_panel]

    def register_tab(self, title: str, widget: QWidget) -> int:
        """Append a tab beside Sensors and Modal q(t); returns its index."""
        if hasattr(widget, "set_session"):
            self.session_widgets.append(widget)
            if self.session is not None:
                widget.set_session(self.session)
        return self.tabs.addTab(widget, title)

    @property
    def time_views(self) -> dict[str, object]:
        """Every view with a time cursor (name -> object with ``cursor_time``)."""
        return {"3d": self.view3d, "sensors": self.sensor_panel, "modal": self.modal_tab,
                "palate": self.palate_panel, "audio": self.audio, "transport": self.transport}

    # -- errors ---------------------------------------------------------------
    def show_error(self, title: str, message: str, path=None) -> None:
        log.warning("%s: %s", title, message)
        self.last_dialog = error_box(self, title, message, path)
        self.statusBar().showMessage(f"{title}: {message}")

    # -- drag and drop ----------------------------------------------------------
    def dragEnterEvent(self, event) -> None:
        if event.mimeData().hasUrls():
            event.acceptProposedAction()

    def dropEvent(self, event) -> None:
        for url in event.mimeData().urls():
            if url.isLocalFile():
                self.open_path(url.toLocalFile())
        event.acceptProposedAction()

    def open_path(self, path) -> None:
        """A recording or, by its extension, a mesh."""
        if str(path).lower().endswith(MESH_SUFFIXES):
            self.open_mesh(path)
        else:
            self.open_recording(path)

    # -- opening ------------------------------------------------------------------
    def ask_open_recording(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open an EMA recording", str(self._last_folder()))
        if path:
            self.open_recording(path)

    def ask_open_with_companions(self) -> None:
        """File ▸ Open with sound/labels: the recording plus an optional WAV and TextGrid."""
        from tonguevis.gui.dialogs import OpenRecordingDialog

        dialog = OpenRecordingDialog(self._last_folder(), self)
        dialog.accepted.connect(lambda: self.open_recording(dialog.paths()[0], audio=dialog.paths()[1],
                                                            labels=dialog.paths()[2]))
        self.last_dialog = dialog
        dialog.open()

    def ask_open_mesh(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open a tetrahedral tongue mesh", str(self._last_folder()))
        if path:
            self.open_mesh(path)

    def _last_folder(self) -> Path:
        recent = self.recent_files()
        return Path(recent[0]).parent if recent else Path.cwd()

    def open_demo(self) -> None:
        from tonguevis.gui.session import demo_recording_path

        path = demo_recording_path()
        if path is None:
            self.show_error("No demo", "no demo recording in data/ (run the demo-corpus script)")
            return
        self.open_recording(path)

    def open_recording(self, path, sensor_map=None, rest=None, audio=None, labels=None) -> bool:
        """Read ``path``; ask for a sensor map if needed; then simulate in the worker.

        ``rest`` (start_s, end_s) is the rest interval to use (checked; None: found as usual);
        ``audio`` and ``labels`` a WAV and a TextGrid (None: those beside the recording).
        """
        self.state.set_playing(False, self)
        try:
            session = load_session(path, sensor_map=sensor_map, rest=rest, audio=audio, labels=labels)
        except (TonguevisError, OSError) as exc:
            self.show_error("Cannot open recording", str(exc), path)
            return False
        self._remember(Path(path).resolve())
        if needs_sensor_map(session.recording):
            dialog = SensorMapDialog(session.recording.sensor_names, path, self)
            dialog.accepted.connect(lambda: self._mapped(session, dialog.mapping()))
            self.last_dialog = dialog
            dialog.open()
            return True
        self.show_session(session)
        return True

    def _mapped(self, session: Session, mapping: dict[str, str]) -> None:
        try:
            session = remap_session(session, mapping)
        except TonguevisError as exc:
            self.show_error("Sensor map not usable", str(exc), session.path)
            return
        self.show_session(session)

    def open_mesh(self, path) -> None:
        from tonguevis.gui.simulation import build_model

        try:
            self.model = build_model(path)
        except (TonguevisError, OSError) as exc:
            self.show_error("Cannot open mesh", str(exc), path)
            return
        except Exception as exc:  # a model that cannot be built from this mesh
            self.show_error("Cannot use mesh", f"{type(exc).__name__}: {exc}", path)
            return
        self.mesh_path = path
        self.statusBar().showMessage(f"mesh {path}: {self.model.mesh.n_nodes} nodes")
        if self.session is not None:
            self._simulate(self.session)

    def show_session(self, session: Session) -> None:
        """Show the recording at once (plots, audio), then simulate it."""
        self.session = session
        self.setWindowTitle(f"tonguevis — {session.name}")
        start, end, period = session.time_range
        self.state.set_range(start, end, period, self)
        self.playback.set_audio(session.recording.audio)
        self.transport.set_productions(session.productions)
        self.audio.show_audio(session.recording.audio, (start, end), session.productions,
                              session.recording.labels)
        self.show_rest(session)
        self._publish()
        self._simulate(session)

    def _publish(self) -> None:
        for widget in self.session_widgets:
            widget.set_session(self.session)
        self.session_changed.emit(self.session)

    # -- simulation in a worker thread --------------------------------------------
    def _simulate(self, session: Session, palate=NO_PALATE) -> None:
        """Simulate ``session`` in the worker, against ``palate`` (default: the window's)."""
        from tonguevis.gui.simulation import build_model, simulate_session

        self._cancel_worker()
        window = self
        palate = self.palate if palate is NO_PALATE else palate
        self._simulating_palate = palate

        def work(progress):
            if window.model is None:
                window.model = build_model(window.mesh_path)
            return simulate_session(session, model=window.model, modes=window.modes, warping=window.warping,
                                    landmarks=window.landmarks, progress=progress, palate=palate)

        self.worker = Worker(work, self)
        dialog = QProgressDialog(f"Simulating {session.name}…", "Cancel", 0, 1000, self)
        dialog.setWindowTitle("tonguevis: simulation")
        dialog.setWindowModality(Qt.WindowModality.WindowModal)
        dialog.setMinimumDuration(300)
        dialog.setValue(0)
        dialog.canceled.connect(self.worker.cancel)
        self.progress_dialog = dialog
        self.worker.progressed.connect(self._on_progress)
        self.worker.succeeded.connect(self._on_simulated)
        self.worker.failed.connect(lambda message: self._on_sim_failed(session, message))
        self.worker.cancelled.connect(self._on_sim_cancelled)
        self.worker.finished.connect(dialog.reset)
        against = "" if palate is None else f" against the {self._palate_name(palate)}"
        self.statusBar().showMessage(f"simulating {session.name} with {self.modes} modes{against}…")
        self.worker.start()

    def _on_progress(self, done: int, total: int, message: str) -> None:
        if self.progress_dialog is not None:
            self.progress_dialog.setMaximum(max(total, 1))
            self.progress_dialog.setValue(min(done, total))
            self.progress_dialog.setLabelText(message)

    def _on_simulated(self, session: Session) -> None:
        if session is not self.session:
            return  # a newer recording was opened meanwhile
        self.palate = session.palate  # a palate chosen becomes the window's once it simulated
        start, end, period = session.time_range
        self.state.set_range(start, end, period, self)
        self.show_rest(session)
        self._publish()
        motion = session.motion
        self.statusBar().showMessage(
            f"{session.name}: {motion.n_frames} frames simulated, "
            f"{int((~motion.converged).sum())} not converged; press Space to play"
            + "".join(f"; {note}" for note in session.notes))
        self.simulation_finished.emit(True)

    def _on_sim_failed(self, session: Session, message: str) -> None:
        palate = getattr(self, "_simulating_palate", None)
        if palate is not None:
            kept = "" if session.motion is None else " The views keep the previous simulation."
            message += (f"\n\n(simulated against the {self._palate_name(palate)}: File ▸ No palate simulates "
                        f"without contact.{kept})")
        self.show_error("Simulation failed", message, session.path)
        self.simulation_finished.emit(False)

    def _on_sim_cancelled(self) -> None:
        self.statusBar().showMessage("simulation cancelled")
        self.simulation_finished.emit(False)

    def _cancel_worker(self) -> None:
        if self.worker is not None and self.worker.isRunning():
            self.worker.cancel()
            self.worker.wait(30000)
        self.worker = None

    # -- exports ------------------------------------------------------------------
    def grab_window(self):
        from tonguevis.gui.export import grab_window

        return grab_window(self)

    def export_screenshot(self, path) -> None:
        from tonguevis.gui.export import atomic_save_image

        atomic_save_image(self.grab_window(), path)
        self.statusBar().showMessage(f"saved {path}")

    def ask_export_screenshot(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Save a screenshot", "tonguevis.png", "PNG (*.png)")
        if path:
            try:
                self.export_screenshot(path)
            except (TonguevisError, OSError) as exc:
                self.show_error("Screenshot not saved", str(exc), path)

    def ask_export_video(self) -> None:
        from tonguevis.gui.export import ask_video

        ask_video(self)

    def ask_export_vtk(self) -> None:
        from tonguevis.gui.export import ask_vtk

        ask_vtk(self)

    def closeEvent(self, event) -> None:
        self.playback.shutdown()
        self._cancel_worker()
        self.view3d.close_view()
        for plot in (self.audio, self.sensor_panel.plot, self.modal_tab.map, self.palate_panel):
            plot.close_plot()
        super().closeEvent(event)
