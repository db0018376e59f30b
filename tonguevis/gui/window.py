"""The main window: 3D views, sensor panel and tabs, audio, transport, menus.

The window holds the app model (:class:`~tonguevis.appstate.AppState`, ``window.state``)
and lays out the views; it does not push data into them.  Opening a recording is
``state.set_session(session)``; changing how the app simulates is ``state.change_run_settings(...)``.
The :class:`~tonguevis.gui.controller.SimulationController` (``window.controller``) follows both and
simulates through the job runner; back on the GUI thread the motion is set on the session and
announced with ``state.set_motion(session)``.  Every view showing a session follows the model
(``state.follow_session(view.set_session)``); the menus' check marks follow ``run_settings`` events;
the status bar shows the model's ``status`` events.
"""

from __future__ import annotations

import os
from pathlib import Path

from PySide6.QtCore import QSettings, Qt, Signal
from PySide6.QtWidgets import QFileDialog, QMainWindow, QSplitter, QTabWidget, QVBoxLayout, QWidget

from tonguevis.appstate import AppState, connected
from tonguevis.errors import TonguevisError
from tonguevis.gui.audio_panel import AudioPlot
from tonguevis.gui.compare_actions import CompareMixin
from tonguevis.gui.dialogs import SensorMapDialog, error_box
from tonguevis.gui.elastic_label import ElasticLabel, ElidingStatusBar
from tonguevis.gui.menus import MenusMixin
from tonguevis.gui.modal_tab import ModalTab
from tonguevis.gui.palate_actions import PalateMixin
from tonguevis.gui.palate_panel import PalatePanel
from tonguevis.gui.playback import PlaybackController
from tonguevis.gui.rest_dialog import RestMixin
from tonguevis.gui.section_panel import SectionPanel
from tonguevis.gui.sensor_panel import SensorPanel
from tonguevis.workflows.session import Session, load_session, needs_sensor_map, remap_session
from tonguevis.gui.transport import TransportBar
from tonguevis.gui.view3d import View3D
from tonguevis.gui.controller import SimulationController

from tonguevis._logging import logger
MESH_SUFFIXES = (".vtu", ".vtk", ".msh", ".node", ".ele", ".mesh", ".npz", ".inp", ".xdmf")

class MainWindow(MenusMixin, CompareMixin, RestMixin, PalateMixin, QMainWindow):
    """The tonguevis window.  ``run_settings`` (a :class:`~tonguevis.sim.settings.RunSettings`; default
    the app model's, everyone's defaults) says how it simulates, ``preferences`` (a QSettings) where it keeps
    the recent files."""

    simulation_finished = Signal(bool)  # True on success (scripts and tests wait for it)
    compare_finished = Signal(bool)  # the compared recording's simulation: True on success

    def __init__(self, state: AppState | None = None, preferences: QSettings | None = None, run_settings=None):
        super().__init__()
        self.setStatusBar(ElidingStatusBar(self))  # its message elided, whole in the tooltip: never cut
        self.setWindowTitle("tonguevis")
        self.resize(1500, 950)
        self.setAcceptDrops(True)
        self.state = state or AppState()
        self.preferences = preferences or QSettings("tonguevis", "tonguevis")
        if run_settings is not None:  # how the app simulates: one RunSettings in the app model
            self.state.set_run_settings(run_settings, self)
        # First: a recording opened starts its simulation before the views draw it.
        self.controller = SimulationController(self)
        self.export_job = None  # the latest export or palate fit (a Job)
        self.last_dialog = None
        self.feature_tabs: dict[str, QWidget] = {}
        connected(self.state.events.status, self._show_status)
        # The window's own reactions first: the time range is the new motion's before any view redraws.
        connected(self.state.events.session, self._session_opened)
        connected(self.state.events.motion, self._motion_ready)
        self._build_views()
        self._build_menus()
        self.playback = PlaybackController(self.state, self)
        self.playback.status.connect(lambda text: self.state.set_status(text, self.playback))
        self.state.set_status("Open a recording (File ▸ Open, or drop a file here)")
        # The views' frame of reference and the palate contact at the cursor: its length changes
        # from frame to frame, and must not resize the window (nor the 3D views) while playing.
        self.frame_status = ElasticLabel("", minimum_width=200)
        self.frame_status.setStyleSheet("QLabel { border-left: 1px solid #b0b0b0; padding-left: 6px; }")
        self.frame_status.setToolTip("the 3D views' frame of reference (View ▸ Head frame / Jaw frame) and, at the "
                                     "cursor, the palate's penetration and contact area")
        self.statusBar().addPermanentWidget(self.frame_status)
        self.view3d.described.connect(self.frame_status.setText)
        self._build_rest_status()

    # -- layout ---------------------------------------------------------------
    def _build_views(self) -> None:
        self.view3d = View3D(self.state, self)
        self.sensor_panel = SensorPanel(self.state, self)
        self.modal_tab = ModalTab(self.state, self)
        self.palate_panel = PalatePanel(self.state, self)
        self.section_panel = SectionPanel(self.state, self)
        self.tabs = QTabWidget()
        self.tabs.addTab(self.sensor_panel, "Sensors")
        self.tabs.addTab(self.modal_tab, "Modal q(t)")
        self.tabs.addTab(self.palate_panel, "Palate")
        self.tabs.addTab(self.section_panel, "Midsagittal")
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
        for view in (self.view3d, self.sensor_panel, self.modal_tab, self.palate_panel, self.section_panel):
            self.state.follow_session(view.set_session)
        self._build_compare_panel(top)  # after the views: it draws into A's scene once A's view has built it

    def register_tab(self, title: str, widget: QWidget) -> int:
        """Append a tab beside Sensors and Modal q(t) (it subscribes to ``state`` itself); returns its index."""
        self.feature_tabs[title] = widget
        return self.tabs.addTab(widget, title)

    @property
    def energy_tab(self):
        return self.feature_tabs.get("Energy")

    @property
    def morph_tab(self):
        return self.feature_tabs.get("Morph")

    @property
    def segmentation_tab(self):
        return self.feature_tabs.get("Segmentation")

    # -- the app model's contents, as the window's -----------------------------------
    @property
    def session(self) -> Session | None:
        """The recording the views show (the model's primary session)."""
        return self.state.session

    @property
    def model(self):
        """The tongue model every simulation uses (the app model's; None: built on first need)."""
        return self.state.tongue_model

    @model.setter
    def model(self, model) -> None:
        self.state.set_tongue_model(model, self.state.mesh_path, self)

    @property
    def mesh_path(self):
        return self.state.mesh_path

    # The run settings' fields, read and written through the app model (the menus and scripts use these;
    # writing one re-simulates the open recordings: the controller follows the model).
    modes = property(lambda self: self.state.run_settings.modes,
                     lambda self, value: self.state.change_run_settings(self, modes=value))
    warping = property(lambda self: self.state.run_settings.warping,
                       lambda self, value: self.state.change_run_settings(self, warping=value))
    landmarks = property(lambda self: self.state.run_settings.landmarks,
                         lambda self, value: self.state.change_run_settings(self, landmarks=value))
    sensor_patches = property(lambda self: self.state.run_settings.sensor_patches,
                              lambda self, value: self.state.change_run_settings(self, sensor_patches=value))
    palate = property(lambda self: self.state.run_settings.palate,
                      lambda self, value: self.state.change_run_settings(self, palate=value))

    @property
    def worker(self):
        """The primary recording's latest simulation job (running or done; None once stopped)."""
        return self.controller.jobs["primary"]

    @property
    def compare_job(self):
        """The compared recording's latest simulation job (running or done; None once stopped)."""
        return self.controller.jobs["compare"]

    @property
    def time_views(self) -> dict[str, object]:
        """Every view with a time cursor (name -> object with ``cursor_time``)."""
        return {"3d": self.view3d, "sensors": self.sensor_panel, "modal": self.modal_tab,
                "palate": self.palate_panel, "audio": self.audio, "transport": self.transport}

    # -- errors ---------------------------------------------------------------
    def show_error(self, title: str, message: str, path=None):
        logger.warning("%s: %s", title, message)
        self.last_dialog = error_box(self, title, message, path)
        self.state.set_status(f"{title}: {message}", self)
        return self.last_dialog

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
        from tonguevis.workflows.session import demo_recording_path

        path = demo_recording_path()
        if path is None:
            self.show_error("No demo", "no demo recording in data/ (run the demo-corpus script)")
            return
        self.open_recording(path)

    def open_recording(self, path, sensor_map=None, rest=None, audio=None, labels=None,
                       options: dict | None = None) -> bool:
        """Read ``path``; ask for a sensor map if needed; then simulate in the worker.

        ``rest`` (start_s, end_s) is the rest interval to use (checked; None: found as usual);
        ``audio`` and ``labels`` a WAV and a TextGrid (None: those beside the recording);
        ``options`` the reader's (``tonguevis view -O``).
        """
        self.state.set_playing(False, self)
        try:
            given = {k: v for k, v in (("audio", audio), ("labels", labels)) if v is not None}  # files win over -O
            session = load_session(path, sensor_map=sensor_map, rest=rest, **{**(options or {}), **given})
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
        from tonguevis.sim.settings import build_model

        try:
            model = build_model(path)  # on the GUI thread: reading a mesh is quick
        except (TonguevisError, OSError) as exc:
            self.show_error("Cannot open mesh", str(exc), path)
            return
        except Exception as exc:  # a model that cannot be built from this mesh
            self.show_error("Cannot use mesh", f"{type(exc).__name__}: {exc}", path)
            return
        same = os.fspath(path) == self.state.mesh_path
        self.state.set_tongue_model(model, os.fspath(path), self)  # a new mesh: the controller re-simulates
        self.state.set_status(f"mesh {path}: {model.mesh.n_nodes} nodes", self)
        if same:  # read again from the same file: the settings did not change, the model did
            self.controller.resimulate()

    def show_session(self, session: Session) -> None:
        """Show the recording at once (plots, audio) while it simulates (the controller starts its job)."""
        self.state.set_session(session, source=self)

    def _session_opened(self, event) -> None:
        """A recording was opened: the window's title, the time range and the rest line (the sound, the
        productions and the views follow the session themselves)."""
        session = event.value
        if event.key != "primary" or session is None:
            return
        self.setWindowTitle(f"tonguevis — {session.name}")
        start, end, period = session.time_range
        self.state.set_range(start, end, period, self)  # first: the views follow the session after it
        self.show_rest(session)

    def _motion_ready(self, event) -> None:
        """The primary recording's simulation is in: its time range and rest line."""
        if event.key != "primary":
            return
        session = event.value
        start, end, period = session.time_range
        self.state.set_range(start, end, period, self)
        self.show_rest(session)

    # -- status ---------------------------------------------------------------------
    def _show_status(self, event) -> None:
        """The status line (elided, whole in its tooltip: the notes after a simulation, plausibility, contact,
        the tongue's size, run past the bar's width)."""
        self.statusBar().showMessage(event.value)

    # -- exports ------------------------------------------------------------------
    def grab_window(self):
        from tonguevis.gui.export import grab_window

        return grab_window(self)

    def export_screenshot(self, path) -> None:
        from tonguevis.gui.export import atomic_save_image

        atomic_save_image(self.grab_window(), path)
        self.state.set_status(f"saved {path}", self)

    def ask_export_screenshot(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Save a screenshot", "tonguevis.png", "PNG (*.png)")
        if path:
            try:
                self.export_screenshot(path)
            except (TonguevisError, OSError) as exc:
                self.show_error("Screenshot not saved", str(exc), path)

    def ask_export_video(self) -> None:
        from tonguevis.gui.export import ask_video

        self.export_job = ask_video(self) or self.export_job

    def ask_export_vtk(self) -> None:
        from tonguevis.gui.export import ask_vtk

        self.export_job = ask_vtk(self) or self.export_job

    def closeEvent(self, event) -> None:
        self.playback.shutdown()
        self.controller.shutdown()
        for tab in self.feature_tabs.values():  # a tab's own job (the measures) ends with the window
            stop = getattr(tab, "stop_worker", None)
            if stop is not None:
                stop()
        self.compare_panel.close_view()
        if self.export_job is not None:
            self.export_job.stop()
        self.view3d.close_view()
        for plot in (self.audio, self.sensor_panel.plot, self.modal_tab.map, self.palate_panel):
            plot.close_plot()
        super().closeEvent(event)
