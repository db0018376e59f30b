"""The live window: the patient's tongue from a live stream, targets, sweeps (issue 25, item 4).

A large 3D view for the patient (the simulated tongue surface, the sensors, the targets
as spheres coloured by their live accuracy, a replay target's ghost), a midsagittal view
(the tongue's section in the plane of its middle, the sensors, the targets, the palate if
given) and a small panel for the clinician (source and connection, "Take rest now",
targets, sweeps, live accuracy, frames per second, latency, dropped frames).

Frames: a :class:`~PySide6.QtCore.QTimer` polls the source every :data:`POLL_MS` ms.  Every
frame received since the last tick is simulated (the dynamics need each frame at its time
step) and, during a sweep, saved; only the newest is drawn, the older ones are counted as
dropped from the display: the window never works through a backlog.  The rest is taken
automatically from the stillest half second of the first :data:`AUTO_REST_S` s, or by the
button (the last half second).  Display smoothing (a first-order low-pass of the drawn points,
off by default) changes only the screen, never what is saved.

Latency of a drawn frame: from its bytes' arrival at the socket (``LiveFrame.arrival_s``) to
the end of the paint of the view that shows it (after VTK's render returns and the image is
painted): :attr:`LiveWindow.latencies_ms`.  Errors (cannot connect, a malformed stream,
a rest that cannot be taken) go to the status line, never into a crash.
"""

from __future__ import annotations

import time
from collections import deque
from pathlib import Path

import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QCheckBox, QDoubleSpinBox, QFormLayout, QGroupBox, QHBoxLayout, QLineEdit, QListWidget, QMainWindow,
    QMessageBox, QPushButton, QScrollArea, QSplitter, QVBoxLayout, QWidget,
)

from tonguevis.errors import TonguevisError
from tonguevis.gui.elastic_label import WrappingLabel
from tonguevis.gui.flow_layout import FlowLayout
from tonguevis.gui.midsagittal_view import BACKGROUND, GHOST_COLOUR, SENSOR_COLOUR, TONGUE_COLOUR, MidsagittalView
from tonguevis.gui.palatogram_view import PalatogramView
from tonguevis.gui.qt_workarounds import keep_none_alive
from tonguevis.live.simulator import REST_SEARCH_S, REST_WINDOW_S, LiveSimulationError, LiveSimulator
from tonguevis.live.targets import (
    FollowingTarget, OscillatingTarget, ReplayTarget, StaticTarget, TargetError, accuracy_colour,
)

from tonguevis._logging import logger

#: How often the source is polled (ms): a frame waits at most this long before it is simulated.
POLL_MS = 2
#: The rest is taken by itself from the stillest half second of the first seconds of the stream.
AUTO_REST_S = REST_SEARCH_S
#: Latencies and frame times kept for the panel's figures.
HISTORY = 600
#: s between two palatograms computed (a few ms each): the clinician reads it, it need not follow every frame.
EPG_EVERY_S = 0.05
#: Frames simulated in one tick at most: after a stall the older ones of a burst are skipped (and counted).
MAX_BURST = 50
DEFAULT_RADIUS_MM = 5.0


def parse_source(text: str, default_port: int = 3030) -> tuple[str, int]:
    """(host, port) of "HOST:PORT", "HOST" or "[v6]:PORT" (TonguevisError when the port is not a number)."""
    text = text.strip()
    if not text:
        raise TonguevisError("give the live source as HOST:PORT (e.g. 127.0.0.1:3030)")
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        port = rest.lstrip(":") or str(default_port)
    elif text.count(":") == 1:
        host, port = text.split(":")
    else:
        host, port = text, str(default_port)
    try:
        number = int(port)
    except ValueError:
        raise TonguevisError(f"the live source's port must be a number, got {port!r} in {text!r}") from None
    if not 0 < number < 65536:
        raise TonguevisError(f"the live source's port must be 1-65535, got {number}")
    return host or "127.0.0.1", number


#: The live 3D view renders at this share of its pixels in each direction and is drawn scaled up:
#: under software OpenGL the render is most of the latency and goes with the pixels (0.8: 36 % fewer).
LIVE_RENDER_SCALE = 0.8


class LiveWindow(QMainWindow):
    """The live view of ``source`` (a started or unstarted :class:`~tonguevis.live.source.Source`, or None
    to connect from the panel).

    sensor_names : the stream's slot names: a list in slot order, or a sensor map (name -> NDI Id);
        without it the names the device sends (see :meth:`slot_names`).  settings : a :class:`~tonguevis.sim.settings.RunSettings`
        (default everyone's: the replay's); its ``palate`` is drawn, its ``rest`` (START, END on the stream's
        clock from the first frame) taken when the stream passes END instead of the stillest moment; model : the
        unplaced tongue model.
    profile : a :class:`~tonguevis.live.profiles.Profile` (its targets, offsets; sweeps saved in its
        folder under ``profiles_root``); None: the profile "default" there (made when first saved).
    auto_rest : take the rest by itself from the stillest half second of the first seconds.
    """

    def __init__(self, source=None, sensor_names=None, settings=None, model=None, profile=None,
                 profiles_root=None, auto_rest: bool = True, parent=None):
        super().__init__(parent)
        keep_none_alive()
        from tonguevis.live.simulator import check_live_settings
        from tonguevis.sim.settings import RunSettings

        self.setWindowTitle("tonguevis live")
        settings = settings if settings is not None else RunSettings()
        check_live_settings(settings)
        self.settings, self.model = settings, model
        self.given_names = (dict(sensor_names) if isinstance(sensor_names, dict) else list(sensor_names)) \
            if sensor_names else None
        self.profiles_root = profiles_root
        self.profile = profile if profile is not None else self._default_profile()
        self.targets = list(self.profile.targets)
        self.auto_rest = auto_rest
        self.palate = settings.palate_surface()
        self.source = None
        self.simulator: LiveSimulator | None = None
        self.sweep = None
        self.last_saved = None
        self.smoothing = 0.0  # s (0: off)
        self._smoothed: dict[str, np.ndarray] = {}
        self._recent: deque = deque(maxlen=int(REST_SEARCH_S * 200))
        self._reset_counters()
        self._build()
        self.timer = QTimer(self)
        self.timer.setTimerType(Qt.TimerType.PreciseTimer)
        self.timer.timeout.connect(self.tick)
        if source is not None:
            self.set_source(source)

    # ------------------------------------------------------------------ set-up
    def _default_profile(self):
        from tonguevis.live.profiles import Profile, ProfileError, load_profile

        try:
            return load_profile("default", self.profiles_root)
        except ProfileError:
            return Profile("default", name="default")

    def _reset_counters(self) -> None:
        self.frames_drawn = 0
        self.frames_received = 0
        self.dropped_frames = 0  # received but not drawn (a newer one came in the same tick)
        self.skipped_frames = 0  # not even simulated (a burst after a stall, beyond MAX_BURST)
        self.latencies_ms: deque = deque(maxlen=HISTORY)
        self.draw_times: deque = deque(maxlen=HISTORY)
        self.stage_ms: deque = deque(maxlen=HISTORY)  # per drawn frame: {"simulate", "reconstruct", "render"}
        self.accuracy: dict[int, float] = {}
        self.last_frame = None
        self._clock0 = None

    def _build(self) -> None:
        from tonguevis.gui.view3d import make_plotter

        from tonguevis.render.scene import set_lights

        split = QSplitter(Qt.Orientation.Horizontal, self)
        self.plotter = make_plotter(split, multi_samples=0, auto_update=False)
        if hasattr(self.plotter, "set_render_scale"):  # the picture drawn from fewer pixels: less latency
            self.plotter.set_render_scale(LIVE_RENDER_SCALE)
        self.plotter.set_background(BACKGROUND)
        renderer = self.plotter.renderer
        # As the app's scene (tonguevis.render.scene): under software OpenGL, VTK's order-independent
        # transparency costs extra full-screen passes (it more than doubled this view's render), the
        # frustum culler re-runs every moving actor's pipeline, and each light is paid per pixel.
        renderer.SetUseOIT(False)
        renderer.GetCullers().RemoveAllItems()
        set_lights(renderer)
        # The targets in a layer over the scene, with the same camera: a target inside or behind the tongue
        # (where the tip is to go) stays in sight, as the patient must see it.
        import vtk

        self.overlay = vtk.vtkRenderer()
        self.overlay.SetLayer(1)
        self.overlay.InteractiveOff()
        self.overlay.SetActiveCamera(renderer.GetActiveCamera())
        self.overlay.SetUseOIT(False)
        self.overlay.GetCullers().RemoveAllItems()
        set_lights(self.overlay)
        self.plotter.ren_win.SetNumberOfLayers(2)
        self.plotter.ren_win.AddRenderer(self.overlay)
        split.addWidget(self.plotter.interactor)
        side = QSplitter(Qt.Orientation.Vertical, split)
        views = QSplitter(Qt.Orientation.Horizontal, side)
        self.midsagittal = MidsagittalView(views)
        self.palatogram = PalatogramView(views)
        views.addWidget(self.midsagittal)
        views.addWidget(self.palatogram)
        views.setSizes([230, 110])
        self.palatogram.setVisible(self.palate is not None)
        side.addWidget(views)
        side.addWidget(self._panel(side))
        side.setSizes([300, 500])
        split.addWidget(side)
        split.setStretchFactor(0, 3)
        split.setStretchFactor(1, 1)
        split.setSizes([900, 340])
        self.setCentralWidget(split)
        self.resize(1280, 800)
        self.surface_mesh = None
        self.sensor_mesh = None
        self.target_actors: list = []
        self.ghost_mesh = None
        self.status_label = self.statusBar()
        self.shown_palate = None  # the palate as placed on the rest (a ShownPalate), once a rest is taken
        self.jaw_mesh = None
        self._jaw_rest = None
        self._epg = None  # (layout, upper-surface indices into the simulator's surface, triangles)
        self._epg_at = -1.0

    def _panel(self, parent) -> QWidget:
        scroll = QScrollArea(parent)
        scroll.setWidgetResizable(True)
        # Scrolled up and down only: its rows wrap to the panel's width (a horizontal scroll bar hid the
        # Connect button and cut the rest's line at 1280 pixels).
        scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        body = QWidget()
        layout = QVBoxLayout(body)
        # Source
        box = QGroupBox("Source")
        form = QFormLayout(box)
        row = QHBoxLayout()
        self.source_edit = QLineEdit("127.0.0.1:3030")
        self.source_edit.setMinimumWidth(90)  # it gives way, not the Connect button
        self.connect_button = QPushButton("Connect")
        self.connect_button.clicked.connect(self.connect_from_panel)
        row.addWidget(self.source_edit)
        row.addWidget(self.connect_button)
        form.addRow("host:port", row)
        self.connection_label = WrappingLabel("not connected")
        form.addRow("status", self.connection_label)
        layout.addWidget(box)
        # Rest
        box = QGroupBox("Rest")
        form = QFormLayout(box)
        self.rest_button = QPushButton("Take rest now")
        self.rest_button.clicked.connect(self.take_rest_now)
        self.rest_label = WrappingLabel("waiting for a still moment")
        form.addRow(self.rest_button)
        form.addRow(self.rest_label)
        layout.addWidget(box)
        # Targets
        box = QGroupBox("Targets")
        v = QVBoxLayout(box)
        self.target_list = QListWidget()
        v.addWidget(self.target_list)
        form = QFormLayout()
        self.radius_spin = QDoubleSpinBox(minimum=1.0, maximum=50.0, value=DEFAULT_RADIUS_MM, suffix=" mm")
        self.frequency_spin = QDoubleSpinBox(minimum=0.1, maximum=10.0, value=1.0, suffix=" Hz")
        form.addRow("radius", self.radius_spin)
        form.addRow("oscillation", self.frequency_spin)
        v.addLayout(form)
        row = FlowLayout()
        for text, slot in (("Static at tip", self.add_static_target), ("Oscillating", self.add_oscillating_target),
                           ("Following", self.add_following_target), ("Remove", self.remove_target)):
            button = QPushButton(text)
            button.clicked.connect(slot)
            row.addWidget(button)
        v.addLayout(row)
        layout.addWidget(box)
        # Sweep
        box = QGroupBox("Sweep")
        form = QFormLayout(box)
        self.sweep_name = QLineEdit("sweep")
        form.addRow("name", self.sweep_name)
        row = QHBoxLayout()
        self.start_button = QPushButton("Start")
        self.stop_button = QPushButton("Stop")
        self.stop_button.setEnabled(False)
        self.start_button.clicked.connect(self.start_sweep)
        self.stop_button.clicked.connect(self.stop_sweep)
        row.addWidget(self.start_button)
        row.addWidget(self.stop_button)
        form.addRow(row)
        self.sweep_label = WrappingLabel("")
        form.addRow(self.sweep_label)
        layout.addWidget(box)
        # Display
        box = QGroupBox("Display")
        form = QFormLayout(box)
        self.smooth_check = QCheckBox("smooth the display (files stay raw)")
        self.smooth_spin = QDoubleSpinBox(minimum=0.005, maximum=0.5, value=0.03, singleStep=0.01, suffix=" s")
        self.smooth_check.toggled.connect(self._smoothing_changed)
        self.smooth_spin.valueChanged.connect(self._smoothing_changed)
        form.addRow(self.smooth_check)
        form.addRow("time constant", self.smooth_spin)
        self.figures_label = WrappingLabel("")
        form.addRow(self.figures_label)
        layout.addWidget(box)
        layout.addStretch(1)
        scroll.setWidget(body)
        self._refresh_targets()
        return scroll

    # ------------------------------------------------------------------ the source
    def set_source(self, source) -> None:
        """Use ``source`` (started here if it is not): frames are polled from now on."""
        self.close_source()
        self.source = source
        if hasattr(source, "host"):
            self.source_edit.setText(f"{source.host}:{source.port}")
        try:
            source.start()
        except Exception as exc:  # a source that cannot even start: said, not raised
            self.show_error(f"cannot start the live source: {exc}")
            return
        self._reset_counters()
        self.timer.start(POLL_MS)

    def connect_from_panel(self) -> None:
        """Connect to the host:port typed in the panel (a WaveFront source)."""
        from tonguevis.live.source import WaveFrontSource

        try:
            host, port = parse_source(self.source_edit.text())
        except TonguevisError as exc:
            self.show_error(str(exc))
            return
        self.set_source(WaveFrontSource(host, port))

    def close_source(self) -> None:
        self.timer.stop() if hasattr(self, "timer") else None
        if self.source is not None:
            try:
                self.source.close()
            except Exception:  # closing must never fail the window
                logger.exception("closing the live source failed")
        self.source = None

    def slot_names(self, n_slots: int) -> list[str]:
        """The stream's slot names: a sensor map given (name -> NDI Id, matched to the ids the device listed,
        else to the slot numbers) or a list given, else the names the device sent, else the profile's map
        (name -> slot), else slot0, slot1, ..."""
        given = self.given_names
        if isinstance(given, dict) and given:
            ids = getattr(self.source, "sensor_ids", None)
            ids = list(ids) if ids and len(ids) == n_slots else list(range(n_slots))
            by_id = {int(i): str(name) for name, i in given.items()}
            return [by_id.get(int(i), f"slot{k}") for k, i in enumerate(ids)]
        if given and len(given) >= n_slots:
            return [str(n) for n in given[:n_slots]]
        names = getattr(self.source, "sensor_names", None)
        if names and len(names) == n_slots:
            return list(names)
        if self.profile.sensor_map:
            by_slot = {slot: name for name, slot in self.profile.sensor_map.items()}
            return [by_slot.get(k, f"slot{k}") for k in range(n_slots)]
        return [f"slot{k}" for k in range(n_slots)]

    # ------------------------------------------------------------------ the frame loop
    def _pending(self) -> list:
        """Every frame received since the last tick (oldest first); the newest alone without a queue."""
        source = self.source
        frames = []
        if getattr(source, "_queue", None) is not None:
            while True:
                frame = source.get(0)
                if frame is None:
                    break
                frames.append(frame)
        else:
            frame = source.latest()
            if frame is not None and (self.last_frame is None or frame.frame != self.last_frame.frame):
                frames.append(frame)
        return frames

    def tick(self) -> None:
        """One poll: simulate what came, draw the newest frame, update the figures (never raises)."""
        if self.source is None:
            return
        try:
            frames = self._pending()
            if frames:
                self._process(frames)
            now = time.perf_counter()
            if now - getattr(self, "_last_status", 0.0) > 0.25:
                self._last_status = now
                self._update_status()
        except Exception as exc:  # a bug or a bad frame must not take the clinic's window down
            logger.exception("live view: a frame could not be shown")
            self.show_status(f"a frame could not be shown: {exc}")

    def _process(self, frames: list) -> None:
        t_start = time.perf_counter()
        self.frames_received += len(frames)
        if len(frames) > MAX_BURST:
            self.skipped_frames += len(frames) - MAX_BURST
            frames = frames[-MAX_BURST:]
        newest = frames[-1]
        names = self.slot_names(newest.n_sensors)
        for frame in frames:
            self._recent.append((frame.timestamp_s, np.asarray(frame.positions, dtype=np.float64)))
        if self._clock0 is None:
            self._clock0 = frames[0].timestamp_s  # the first frame kept (a burst holds several)
        if self.simulator is None and self.auto_rest and len(self._recent) >= 2:
            given = self.settings.rest
            if given is not None:  # the rest the user gave: when the stream has passed its end
                if newest.timestamp_s - self._clock0 >= given[1]:
                    self._take_rest(names, stillest=False, interval=given)
            elif self._recent[-1][0] - self._recent[0][0] >= AUTO_REST_S - 1e-9:
                self._take_rest(names, stillest=True)
        step = None
        simulate_s = 0.0
        sim = self.simulator
        if sim is not None and sim.sensor_names != names:
            self.simulator = sim = None  # the slots changed (another device): a new rest is needed
            self.rest_label.setText("the stream's sensors changed: take the rest again")
        corrected = []
        for k, frame in enumerate(frames):
            if sim is not None:
                try:
                    step = sim.step(frame.positions, reconstruct=k == len(frames) - 1)
                except (LiveSimulationError, ValueError, np.linalg.LinAlgError) as exc:
                    self.show_status(f"simulation stopped: {exc}")
                    self.simulator = sim = None
                    step = None
                else:
                    simulate_s += sum(v for key, v in step.timings.items() if key != "reconstruct")
                    corrected.append(step.corrected)
            if self.sweep is not None:
                self._add_to_sweep(frame, corrected[-1] if sim is not None and corrected else None)
        self.dropped_frames += len(frames) - 1
        self._draw(newest, names, step)
        t_drawn = time.perf_counter()
        self.frames_drawn += 1
        self.last_frame = newest
        self.latencies_ms.append(1e3 * (t_drawn - newest.arrival_s))
        self.draw_times.append(t_drawn)
        self.stage_ms[-1]["simulate"] = 1e3 * simulate_s
        self.stage_ms[-1]["pending"] = len(frames)  # frames this tick took from the source (1: no backlog)
        self.stage_ms[-1]["tick"] = 1e3 * (t_drawn - t_start)

    def _add_to_sweep(self, frame, corrected) -> None:
        from tonguevis.live.sweeps import SweepError

        sweep = self.sweep
        try:
            if sweep._live_correction is False:
                corrected = None
            elif sweep._live_correction and corrected is None:
                return  # the simulation stopped mid-sweep: keep the sweep consistent (raw only from before)
            self.accuracy = dict(enumerate(sweep.add_frame(frame, corrected=corrected)))
        except SweepError as exc:
            self.show_status(f"sweep: frame {frame.frame} not added ({exc})")
        if sweep.finished:
            self.stop_sweep()

    # ------------------------------------------------------------------ drawing
    def _low_pass(self, key: str, value: np.ndarray, dt: float) -> np.ndarray:
        """First-order low-pass of what is drawn (off: the value itself)."""
        if self.smoothing <= 0:
            return value
        old = self._smoothed.get(key)
        if old is None or old.shape != value.shape:
            self._smoothed[key] = np.array(value, dtype=np.float64)
            return value
        alpha = 1.0 - np.exp(-max(dt, 0.0) / self.smoothing)
        fresh = np.isfinite(old)
        old[fresh] += alpha * (value[fresh] - old[fresh])
        old[~fresh] = value[~fresh]
        return old

    def _draw(self, frame, names: list[str], step) -> None:
        import pyvista as pv

        t0 = time.perf_counter()
        dt = 0.0 if self.last_frame is None else frame.timestamp_s - self.last_frame.timestamp_s
        sim = self.simulator
        if step is not None and sim is not None:
            shift = step.jaw_offset
            surface = self._low_pass("surface", step.surface + shift, dt)
            sensors_head = step.corrected
            drawn_sensors = self._low_pass("sensors", sim.sensor_points_in_view(step), dt)
            if self.surface_mesh is None:
                faces = np.hstack([np.full((len(sim.surface_faces), 1), 3), sim.surface_faces]).ravel()
                from tonguevis.render.surface_geometry import VertexNormals, outward_normals

                # Lit on the CPU at the vertices and drawn unlit, its hidden back faces culled (as the app's
                # scene: VTK's per-pixel lighting in software costs more than the 736 vertices' shading).
                self._normals = VertexNormals(sim.surface_faces, len(surface))
                self._normal_sign = 1.0 if np.allclose(outward_normals(sim.rest_surface, sim.surface_faces),
                                                       self._normals(sim.rest_surface)) else -1.0
                self.surface_mesh = pv.PolyData(np.array(surface, dtype=np.float32), faces)
                self.surface_mesh.point_data["colours"] = self._shaded(surface)
                self.plotter.add_mesh(self.surface_mesh, scalars="colours", rgb=True, name="tongue",
                                      lighting=False, culling="back" if self._normal_sign > 0 else "front")
                rest = sim.rest_surface
                centre = rest.mean(axis=0)
                # The app's main view: from the front right and above (x anterior, y left, z up), the tongue fitted.
                self.plotter.camera_position = [tuple(centre + np.array([0.55, -1.0, 0.55])), tuple(centre), (0, 0, 1)]
                lo, hi = rest.min(axis=0), rest.max(axis=0)
                self.plotter.renderer.ResetCamera(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])  # the tongue alone
                self.plotter.camera.zoom(1.4)
                self.surface_mesh.point_data["colours"][:] = self._shaded(surface)
                self.midsagittal.set_bounds(rest[:, [0, 2]], margin=0.35)
                self._mid_y = float(np.median(rest[:, 1]))
                self._show_context(sim)
            else:
                self.surface_mesh.points[:] = surface
                self.surface_mesh.point_data["colours"][:] = self._shaded(surface)
                self.surface_mesh.Modified()
            if self.jaw_mesh is not None:
                self.jaw_mesh.points[:] = self._jaw_rest + np.asarray(shift, dtype=np.float32)
                self.jaw_mesh.Modified()
        else:
            sensors_head = np.asarray(frame.positions, dtype=np.float64) / 1000.0
            drawn_sensors = self._low_pass("sensors", sensors_head, dt)
            surface = None
        if self.sensor_mesh is None:
            self.sensor_mesh = pv.PolyData(np.nan_to_num(np.array(drawn_sensors, dtype=np.float32)))
            self.plotter.add_mesh(self.sensor_mesh, color=SENSOR_COLOUR, point_size=14, render_points_as_spheres=True,
                                  name="sensors")
            if surface is None:
                self.plotter.reset_camera()
        elif len(self.sensor_mesh.points) == len(drawn_sensors):
            self.sensor_mesh.points[:] = np.nan_to_num(drawn_sensors)
            self.sensor_mesh.Modified()
        else:
            self.plotter.remove_actor("sensors")
            self.sensor_mesh = None
        t1 = time.perf_counter()
        self._draw_targets(frame, names, sensors_head)
        t2 = time.perf_counter()
        # VTK's render returns once the frame is submitted; Mesa rasterises it on its own threads while
        # the midsagittal section is computed here, then the paint reads it back and shows it.
        self.plotter.render()
        t3 = time.perf_counter()
        if surface is not None:
            from tonguevis.analysis.section import plane_section

            self.midsagittal.segments = plane_section(surface, sim.surface_faces, self._mid_y)
            self.midsagittal.sensors = np.asarray(drawn_sensors)[:, [0, 2]]
        self.midsagittal.update()  # painted at the next turn of the event loop, after the 3D view
        t4 = time.perf_counter()
        self._paint()
        t5 = time.perf_counter()
        if step is not None and self._epg is not None and frame.timestamp_s - self._epg_at >= EPG_EVERY_S:
            self._show_palatogram(step, frame)
        self.stage_ms.append({"reconstruct": 1e3 * (step.timings["reconstruct"] if step is not None else 0.0),
                              "scene": 1e3 * (t2 - t0 + t4 - t3), "render": 1e3 * (t3 - t2 + t5 - t4),
                              "submit": 1e3 * (t3 - t2), "paint": 1e3 * (t5 - t4), "targets": 1e3 * (t2 - t1)})

    def _show_context(self, sim) -> None:
        """Once the rest is taken: the palate as the simulator placed it (3D and the midsagittal section, traced
        and estimated told apart), the jaw, and what the palatogram needs."""
        import pyvista as pv

        from tonguevis.render.scene import context_surfaces

        for name in ("palate", "jaw"):
            self.plotter.remove_actor(name)
        jaw = context_surfaces(None, sim.model).get("jaw")
        if jaw is not None:
            self.jaw_mesh = jaw
            self._jaw_rest = np.array(jaw.points, dtype=np.float32)
            self.plotter.add_mesh(jaw, color="#c8c8c8", opacity=0.25, name="jaw", lighting=True,
                                  culling="back")
        self.shown_palate = self._epg = None
        if sim.palate is None:
            return
        from tonguevis.analysis.epg import epg_layout, upper_surface
        from tonguevis.render.drawing import generic_shown, palate_label, speaker_palate
        from tonguevis.render.midsagittal import palate_sections

        if sim.palate.metadata.get("generic"):
            shown = generic_shown(True, sim.model)
        else:
            shown = speaker_palate(sim.palate, palate_label(self.settings.palate))
        self.shown_palate = shown
        if shown is not None:
            faces = np.hstack([np.full((len(shown.faces), 1), 3), shown.faces]).ravel()
            self.plotter.add_mesh(pv.PolyData(np.asarray(shown.points, dtype=np.float32), faces), color="#8fc1e3",
                                  opacity=0.3, name="palate", culling="back")
            self.midsagittal.palate, self.midsagittal.palate_estimated = palate_sections(shown, self._mid_y)
        try:
            nodes, triangles = upper_surface(sim.model)
            self._epg = (epg_layout(sim.palate), np.searchsorted(sim.surface_nodes, nodes), triangles)
        except Exception as exc:  # the palatogram is an extra: the live view goes on without it
            logger.info("no live palatogram: %s", exc)
            self.palatogram.show_contacts(None, "no electrode layout on this palate")

    def _show_palatogram(self, step, frame) -> None:
        """The palatogram of the frame just drawn (the simulated surface, not the display's smoothing)."""
        from tonguevis.analysis.epg import electrode_contacts

        layout, index, triangles = self._epg
        surface = (np.asarray(step.surface, dtype=np.float64) + step.jaw_offset)[index]
        contacts = electrode_contacts(surface[None], triangles, self.simulator.palate, layout)[0]
        self._epg_at = frame.timestamp_s
        self.palatogram.show_contacts(contacts, f"t = {self._clock(frame):.2f} s")

    def _shaded(self, surface: np.ndarray) -> np.ndarray:
        """(k, 3) uint8 colours of the tongue's vertices lit by the view's lights for the camera now."""
        from matplotlib.colors import to_rgb

        from tonguevis.render.scene import LIGHTS, TONGUE_MATERIAL
        from tonguevis.render.shading import shade

        camera = self.plotter.renderer.GetActiveCamera()
        view = np.array([[camera.GetViewTransformMatrix().GetElement(i, j) for j in range(4)] for i in range(4)])
        normals = self._normal_sign * self._normals(surface)
        return shade(np.array(to_rgb(TONGUE_COLOUR)), normals, surface, view, LIGHTS, **TONGUE_MATERIAL)

    def _render(self) -> None:
        """Render the 3D view now and paint it (synchronously: the frame is on screen when this returns)."""
        self.plotter.render()
        self._paint()

    def _paint(self) -> None:
        """Paint the 3D view rendered last, now."""
        # Painted now, not at the next turn of the event loop: the image views read the frame back and
        # draw it, the QOpenGLWidget composes it.  (Not QApplication.processEvents(): called at this rate,
        # PySide6 6.12's wrapper drops a reference to None each time until Python aborts.)
        self.plotter.interactor.repaint()

    def _sensor_dict(self, names: list[str], positions: np.ndarray) -> dict[str, np.ndarray]:
        from tonguevis.live.profiles import apply_sensor_offsets

        return apply_sensor_offsets({n: positions[k] for k, n in enumerate(names)}, self.profile.sensor_offsets)

    def _clock(self, frame) -> float:
        if self.sweep is not None and self.sweep.start_s is not None:
            return frame.timestamp_s - self.sweep.start_s
        return frame.timestamp_s - (self._clock0 or 0.0)

    def _draw_targets(self, frame, names: list[str], sensors_head: np.ndarray) -> None:
        import pyvista as pv

        sensors = self._sensor_dict(names, sensors_head)
        t = self._clock(frame)
        shown = []
        while len(self.target_actors) > len(self.targets):
            self.overlay.RemoveActor(self.target_actors.pop())
        ghost = None
        for j, target in enumerate(self.targets):
            try:
                centre = target.position_at(t, sensors)
                if self.sweep is None:
                    _, acc = target.score(t, sensors)
                    self.accuracy[j] = float(acc)
            except TargetError as exc:
                self.show_status(str(exc))
                centre = np.full(3, np.nan)
            acc = self.accuracy.get(j, np.nan)
            rgb = tuple(float(c) for c in accuracy_colour(acc))
            if j >= len(self.target_actors):
                sphere = pv.Sphere(radius=target.radius, theta_resolution=24, phi_resolution=16)
                actor = pv.Actor(mapper=pv.DataSetMapper(sphere))
                actor.prop.opacity = max(target.opacity, 0.35)
                actor.prop.specular = 0.3
                self.overlay.AddActor(actor)
                self.target_actors.append(actor)
            actor = self.target_actors[j]
            actor.prop.color = rgb
            finite = np.all(np.isfinite(centre))
            actor.SetVisibility(bool(finite))
            if finite:
                actor.SetPosition(*centre)
            shown.append((centre[0], centre[2], target.radius, rgb))
            if isinstance(target, ReplayTarget) and target.template and ghost is None:
                ghost = target.ghost_at(t)
        self.midsagittal.targets = shown
        self._draw_ghost(ghost)
        if self.frames_drawn % 10 == 0:
            self._refresh_target_figures()

    def _draw_ghost(self, ghost) -> None:
        """The replay target's template sensors (the ghost tongue), translucent, joined tip to back."""
        import pyvista as pv

        if not ghost:
            if self.ghost_mesh is not None:
                self.plotter.remove_actor("ghost")
                self.ghost_mesh = None
            self.midsagittal.ghost = np.zeros((0, 2))
            return
        # The midline sensors joined tip to back (the ghost's profile); the others are not drawn.
        order = [n for n in ("TT", "TB", "TM", "TD", "TBK") if n in ghost] or list(ghost)
        points = np.nan_to_num(np.array([ghost[n] for n in order], dtype=np.float32))
        if self.ghost_mesh is None or len(self.ghost_mesh.points) != len(points):
            self.ghost_mesh = pv.lines_from_points(points) if len(points) > 1 else pv.PolyData(points)
            self.plotter.add_mesh(self.ghost_mesh, color=GHOST_COLOUR, opacity=0.6, line_width=4, point_size=12,
                                  render_points_as_spheres=True, render_lines_as_tubes=True, name="ghost")
        else:
            self.ghost_mesh.points[:] = points
            self.ghost_mesh.Modified()
        self.midsagittal.ghost = points[:, [0, 2]]

    # ------------------------------------------------------------------ the rest
    def _take_rest(self, names: list[str], stillest: bool, interval=None) -> bool:
        """The rest from the stillest moment of the recent frames, the last half second, or ``interval``
        (start_s, end_s on the stream's clock from its first frame)."""
        recent = list(self._recent)
        times = np.array([t for t, _ in recent])
        if len(times) < 2:
            self.show_status("no frames yet to take the rest from")
            return False
        dt = float(np.median(np.diff(times)))
        rate = round(1.0 / dt, 3) if dt > 0 else 100.0
        try:
            sim = LiveSimulator(names, self.settings, model=self.model, rate=rate)
            if self.model is None:
                self.model = sim.source_model  # built once, kept for the next rest
            if stillest:
                for t, p in recent:
                    sim.observe(t, p)
                sim.take_rest(REST_WINDOW_S)
            elif interval is not None:
                start, end = (self._clock0 or 0.0) + interval[0], (self._clock0 or 0.0) + interval[1]
                inside = (times >= start - 1e-9) & (times <= end + 1e-9)
                if inside.sum() < 2:
                    raise LiveSimulationError(f"the rest {interval[0]:g}-{interval[1]:g} s (--rest) holds "
                                              f"{int(inside.sum())} frame(s) of the stream; give a longer one")
                sim.set_rest(times[inside], np.stack([p for (_, p), keep in zip(recent, inside) if keep]))
            else:
                last = times >= times[-1] - REST_WINDOW_S
                sim.set_rest(times[last], np.stack([p for (_, p), keep in zip(recent, last) if keep]))
        except (TonguevisError, ValueError) as exc:
            self.auto_rest = False  # said once; the clinician presses the button when the patient is still
            self.rest_label.setText(f"no rest: {exc}")
            self.show_status(f"cannot take the rest: {exc}")
            return False
        self.simulator = sim
        self._smoothed.clear()
        if self.surface_mesh is not None:
            self.plotter.remove_actor("tongue")
            self.surface_mesh = None
        # On this window's clock (0 at its first frame, as a given rest is), not the device's or a looping
        # replay server's, whose time stamps run on from wherever it was (40 s into a 17 s recording's third lap).
        origin = self._clock0 if self._clock0 is not None else sim.rest_times[0]
        start, end = sim.rest_times[0] - origin, sim.rest_times[-1] - origin
        how = "(stillest moment)" if stillest else "(as given)" if interval is not None else "taken"
        self.rest_label.setText(f"rest {how}: {start:.2f}-{end:.2f} s "
                                f"after the first frame; {len(sim.driving_names)} sensors drive the tongue "
                                f"({', '.join(sim.driving_names)}), {self.settings.modes} modes")
        self.show_status("rest taken")
        return True

    def take_rest_now(self) -> bool:
        """The rest from the last half second (the patient holds still when the button is pressed)."""
        if self.last_frame is None:
            self.show_status("no frames yet to take the rest from")
            return False
        return self._take_rest(self.slot_names(self.last_frame.n_sensors), stillest=False)

    # ------------------------------------------------------------------ targets
    def _tip(self) -> tuple[str, np.ndarray] | None:
        """(scored sensor, its head-frame position m now) for new targets; None (said) when unknown."""
        frame = self.last_frame
        if frame is None:
            self.show_status("no frame yet: targets are placed at the tongue tip's current position")
            return None
        names = self.slot_names(frame.n_sensors)
        sensor = "TT" if "TT" in names else next((n for n in names if n.startswith("T")), names[0])
        if self.simulator is not None and self.simulator.ready:
            position = self.simulator.last_corrected[names.index(sensor)]
        else:
            position = np.asarray(frame.positions[names.index(sensor)], dtype=float) / 1000.0
        position = self._sensor_dict([sensor], position[None])[sensor]
        if not np.all(np.isfinite(position)):
            self.show_status(f"{sensor} is missing now: no target placed")
            return None
        return sensor, position

    def _add_target(self, target) -> None:
        if self.sweep is not None:
            self.show_status("targets are fixed during a sweep: stop it first")
            return
        self.targets.append(target)
        self._targets_changed()

    def add_static_target(self) -> None:
        """A static target at the tongue tip's position now (radius from the panel)."""
        tip = self._tip()
        if tip is not None:
            sensor, p = tip
            self._add_target(StaticTarget(p, self.radius_spin.value() / 1000.0, sensor=sensor,
                                          name=f"static {len(self.targets) + 1}"))

    def add_oscillating_target(self) -> None:
        """A target oscillating between the tip's position now and 10 mm below it (frequency from the panel)."""
        tip = self._tip()
        if tip is not None:
            sensor, p = tip
            self._add_target(OscillatingTarget(p, p - np.array([0.0, 0.0, 0.01]), self.frequency_spin.value(),
                                               self.radius_spin.value() / 1000.0, sensor=sensor,
                                               name=f"oscillating {len(self.targets) + 1}"))

    def add_following_target(self) -> None:
        """A target following the jaw (else a head reference) where the tip is now relative to it."""
        tip = self._tip()
        if tip is None:
            return
        sensor, p = tip
        names = self.slot_names(self.last_frame.n_sensors)
        follows = "JAW" if "JAW" in names else next((n for n in names if n != sensor), None)
        if follows is None:
            self.show_status("a following target needs another sensor to follow")
            return
        positions = self.simulator.last_corrected if self.simulator is not None else \
            np.asarray(self.last_frame.positions, dtype=float) / 1000.0
        anchor = self._sensor_dict(names, positions)[follows]
        if not np.all(np.isfinite(anchor)):
            self.show_status(f"{follows} is missing now: no target placed")
            return
        self._add_target(FollowingTarget(follows, p - anchor, self.radius_spin.value() / 1000.0, sensor=sensor,
                                         name=f"following {follows} {len(self.targets) + 1}"))

    def add_target(self, target) -> None:
        """Add any :class:`~tonguevis.live.targets.Target` (e.g. a ReplayTarget with its ghost)."""
        self._add_target(target)

    def remove_target(self) -> None:
        """Remove the target selected in the list (the last one when none is)."""
        if self.sweep is not None:
            self.show_status("targets are fixed during a sweep: stop it first")
            return
        if not self.targets:
            return
        row = self.target_list.currentRow()
        self.targets.pop(row if 0 <= row < len(self.targets) else -1)
        self._targets_changed()

    def _targets_changed(self) -> None:
        self.accuracy = {}
        for actor in self.target_actors:
            self.overlay.RemoveActor(actor)
        self.target_actors = []
        self.profile.targets = list(self.targets)
        self._refresh_targets()

    def _refresh_targets(self) -> None:
        self.target_list.clear()
        for target in self.targets:
            self.target_list.addItem(f"{target.name} ({target.sensor}, {1000 * target.radius:.0f} mm)")
        self._refresh_target_figures()

    def _refresh_target_figures(self) -> None:
        for j, target in enumerate(self.targets):
            item = self.target_list.item(j)
            if item is None:
                continue
            acc = self.accuracy.get(j, np.nan)
            figure = "—" if not np.isfinite(acc) else f"{acc:.0f} %"
            item.setText(f"{target.name} ({target.sensor}, {1000 * target.radius:.0f} mm): {figure}")
            item.setForeground(QColor.fromRgbF(*(float(c) for c in accuracy_colour(acc))))

    # ------------------------------------------------------------------ sweeps
    def start_sweep(self) -> bool:
        """Start recording a sweep named as in the panel (every frame from now, raw and head-corrected)."""
        from tonguevis.live.sweeps import Sweep, SweepError

        if self.last_frame is None:
            self.show_status("no frames yet: connect to a source first")
            return False
        names = self.slot_names(self.last_frame.n_sensors)
        try:
            self.sweep = Sweep(self.sweep_name.text(), names, profile=self.profile, targets=list(self.targets),
                               axes=getattr(self.source, "axes", None))
        except (SweepError, TargetError) as exc:
            self.show_error(f"cannot start the sweep: {exc}")
            return False
        self.accuracy = {}
        self.start_button.setEnabled(False)
        self.stop_button.setEnabled(True)
        self.sweep_label.setText(f"recording sweep {self.sweep.number} ({self.sweep.name})…")
        return True

    def stop_sweep(self):
        """Stop the sweep and save it into the profile's folder; returns the SavedSweep (None if nothing saved)."""
        from tonguevis.live.profiles import save_profile

        sweep, self.sweep = self.sweep, None
        self.start_button.setEnabled(True)
        self.stop_button.setEnabled(False)
        if sweep is None:
            return None
        try:
            saved = sweep.save(profiles_root=self.profiles_root)
            save_profile(self.profile, self.profiles_root)
        except (TonguevisError, OSError) as exc:
            self.sweep_label.setText(f"sweep {sweep.number} not saved: {exc}")
            self.show_error(f"the sweep could not be saved: {exc}")
            return None
        self.last_saved = saved
        summaries = sweep.summaries()
        means = ", ".join(f"{s.mean_percent:.0f} %" for s in summaries) if summaries else "no targets"
        self.sweep_label.setText(f"sweep {sweep.number} ({sweep.name}): {sweep.n_samples} frames, "
                                 f"{sweep.elapsed_s:.1f} s, accuracy {means}; saved in {saved.folder}")
        return saved

    # ------------------------------------------------------------------ figures and messages
    def figures(self) -> dict:
        """Frames per second, latency (ms: median, p95, max), drawn, received, dropped and skipped frames."""
        lat = np.array(self.latencies_ms)
        times = np.array(self.draw_times)
        fps = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 and times[-1] > times[0] else 0.0
        return {"fps": float(fps), "latency_ms_median": float(np.median(lat)) if len(lat) else float("nan"),
                "latency_ms_p95": float(np.percentile(lat, 95)) if len(lat) else float("nan"),
                "latency_ms_max": float(lat.max()) if len(lat) else float("nan"),
                "frames_drawn": self.frames_drawn, "frames_received": self.frames_received,
                "dropped_frames": self.dropped_frames, "skipped_frames": self.skipped_frames}

    def _update_status(self) -> None:
        status = self.source.status() if self.source is not None else None
        if status is not None:
            text = f"{status.state}: {status.frames} frames"
            if status.reconnects:
                text += f", {status.reconnects} reconnection(s)"
            if status.missed:
                text += f", {status.missed} missed by the device"
            if status.message:
                text += f" — {status.message}"
            self.connection_label.setText(text)
        f = self.figures()
        self.figures_label.setText(
            f"{f['fps']:.0f} frames/s drawn; latency {f['latency_ms_median']:.1f} ms median, "
            f"{f['latency_ms_p95']:.1f} ms p95 (socket to screen); dropped {f['dropped_frames']} "
            f"(not drawn) of {f['frames_received']}")
        self._refresh_target_figures()

    def _smoothing_changed(self, *_args) -> None:
        self.smoothing = self.smooth_spin.value() if self.smooth_check.isChecked() else 0.0
        self._smoothed.clear()

    def show_status(self, text: str) -> None:
        self.statusBar().showMessage(text, 8000)

    def show_error(self, text: str) -> None:
        """Said in the status line, and in a dialog unless running headless (tests, the benchmark)."""
        self.show_status(text)
        logger.warning("live: %s", text)
        from PySide6.QtGui import QGuiApplication

        if QGuiApplication.platformName() not in ("offscreen", "minimal") and not getattr(self, "quiet", False):
            QMessageBox.warning(self, "tonguevis live", text)

    def closeEvent(self, event) -> None:  # noqa: N802 (Qt name)
        if self.sweep is not None:
            self.stop_sweep()
        self.close_source()
        self.plotter.close()
        super().closeEvent(event)


def run_live(address: str | None = None, settings=None, *, sensor_map=None, profile=None) -> int:
    """``tonguevis live``: the live window, connected to ``address`` ("HOST:PORT") at once when given,
    simulating as ``settings`` (a :class:`~tonguevis.sim.settings.RunSettings`: the replay's by default; its
    palate drawn); ``sensor_map`` : name -> NDI Id; ``profile`` : a Profile.  Runs until closed."""
    from tonguevis.gui.application import application, install_error_hook
    from tonguevis.live.source import WaveFrontSource

    source = WaveFrontSource(*parse_source(address)) if address else None
    app = application()
    window = LiveWindow(source, sensor_names=sensor_map, settings=settings, profile=profile)
    install_error_hook(window)
    window.show()
    return app.exec()


def live_view_screenshot(window: LiveWindow, path: str | Path) -> Path:
    """Save the whole window (3D view, midsagittal view and panel) as a PNG."""
    path = Path(path)
    window.grab().save(str(path))
    return path
