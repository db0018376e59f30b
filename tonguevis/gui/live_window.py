"""The live window: views on a live session held by the app's model (issue 25, item 4; issue 34).

A large 3D view for the patient (the simulated tongue surface, the sensors, the targets
as spheres coloured by their live accuracy, a replay target's ghost), a midsagittal view
(the tongue's section in the plane of its middle, the sensors, the targets, the palate if
given), the palatogram, and a small panel for the clinician (source and connection, "Take rest now",
targets, sweeps, live accuracy, frames per second, latency, dropped frames).

What happens lives in a :class:`~tonguevis.live.session.LiveSession` (no Qt: the source, the
simulation, the rest, the targets, the sweep, the counters, the display's low-pass), which the
app's model holds (:attr:`tonguevis.appstate.AppState.live_session`).  This window shows the session
the model holds, redraws from its events, and its buttons call its methods; a
:class:`~PySide6.QtCore.QTimer` calls :meth:`LiveSession.tick` every :data:`POLL_MS` ms, which
simulates every frame received since and hands the newest to the views (the window never works
through a backlog).  The midsagittal and palatogram views are the replay app's.

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

from tonguevis.appstate import AppState, connected
from tonguevis.errors import TonguevisError
from tonguevis.gui.elastic_label import WrappingLabel
from tonguevis.gui.flow_layout import FlowLayout
from tonguevis.gui.qt_workarounds import keep_none_alive
from tonguevis.live.session import AUTO_REST_S, LiveSession  # noqa: F401 (AUTO_REST_S: the tests' import)
from tonguevis.live.targets import accuracy_colour

from tonguevis._logging import logger

#: How often the source is polled (ms): a frame waits at most this long before it is simulated.
POLL_MS = 2
#: Latencies and frame times kept for the panel's figures.
HISTORY = 600
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




class LiveWindow(QMainWindow):
    """The live view of ``source`` (a started or unstarted :class:`~tonguevis.live.source.Source`, or None
    to connect from the panel): the views of a new :class:`~tonguevis.live.session.LiveSession` made of the
    other arguments (see it) and put into ``state`` (an :class:`~tonguevis.appstate.AppState`, the app's;
    default one of its own).  The window then shows whichever live session ``state`` holds.
    """

    def __init__(self, source=None, session: LiveSession | None = None, settings=None, parent=None, *,
                 state: AppState | None = None):
        super().__init__(parent)
        keep_none_alive()
        self.setWindowTitle("tonguevis live")
        # what is simulated, and how, is the session's (its sensors' names, profile, model, rest)
        session = session if session is not None else LiveSession(settings)
        self.state = state if state is not None else AppState()
        self.session: LiveSession | None = None
        self._session_stops: list = []
        self._reset_display_counters()
        self._build(palatogram=session.palate is not None)
        self.timer = QTimer(self)
        self.timer.setTimerType(Qt.TimerType.PreciseTimer)
        self.timer.timeout.connect(self.tick)
        self._stop_following = connected(self.state.events.live_session, lambda event: self._bind(event.value))
        self.state.set_live_session(session, source=self)
        if source is not None:
            self.set_source(source)

    # ------------------------------------------------------------------ the session the model holds
    def _bind(self, session) -> None:
        """Show ``session`` (None: nothing): hear its events, start over the scene and the panel."""
        for stop in self._session_stops:
            stop()
        self.timer.stop()
        if self.session is not None and self.session is not session:  # the model dropped it: it stops
            if self.session.sweep is not None:
                self.session.stop_sweep()
            self.session.close_source()
        self.session = session
        self.views.forget()
        if session is None:
            self._session_stops = []
            return
        events = session.events
        self._session_stops = [
            connected(events.source, self._on_source), connected(events.frame_processed, self._on_frame),
            connected(events.rest_changed, self._on_rest), connected(events.targets_changed, self._on_targets),
            connected(events.sweep_changed, self._on_sweep),
            connected(events.status, lambda event: self.show_status(event.value)),
            connected(events.error, lambda event: self.show_error(event.value)),
        ]
        self.palatogram.setVisible(session.palate is not None)
        self.rest_label.setText(session.rest_line)
        self._refresh_targets()
        self._sweep_buttons()
        if session.source is not None:
            self._source_started(session.source)

    # The session's state, as the window's (what the tests, the benchmark and the menus read).
    source = property(lambda self: self.session.source, doc="The session's source (None: not connected).")
    simulator = property(lambda self: self.session.simulator, doc="The session's LiveSimulator (None: no rest).")
    targets = property(lambda self: self.session.targets, doc="The session's targets.")
    accuracy = property(lambda self: self.session.accuracy, doc="{target index: accuracy %} of the last frame.")
    frames_received = property(lambda self: self.session.frames_received)
    dropped_frames = property(lambda self: self.session.dropped_frames, doc="Received, simulated, not drawn.")
    skipped_frames = property(lambda self: self.session.skipped_frames, doc="Received, not even simulated.")

    def _reset_display_counters(self) -> None:
        self.frames_drawn = 0
        self.latencies_ms: deque = deque(maxlen=HISTORY)
        self.draw_times: deque = deque(maxlen=HISTORY)
        self.stage_ms: deque = deque(maxlen=HISTORY)  # per drawn frame: {"simulate", "reconstruct", "render"...}

    def _reset_counters(self) -> None:
        """Count from now (the session's frames and the display's)."""
        self.session.reset_counters()
        self._reset_display_counters()

    def _build(self, palatogram: bool) -> None:
        from tonguevis.gui.live_views import LiveViews

        split = QSplitter(Qt.Orientation.Horizontal, self)
        side = QSplitter(Qt.Orientation.Vertical, split)
        views = QSplitter(Qt.Orientation.Horizontal, side)
        self.views = LiveViews(split, views)
        # the views' widgets, as the window's (the tests and the benchmark read them)
        self.plotter, self.midsagittal, self.palatogram = self.views.plotter, self.views.midsagittal, self.views.palatogram
        split.addWidget(self.plotter.interactor)
        views.addWidget(self.midsagittal)
        views.addWidget(self.palatogram)
        views.setSizes([230, 110])
        self.palatogram.setVisible(palatogram)  # before the sizes are set: the panel's width follows
        side.addWidget(views)
        side.addWidget(self._panel(side))
        side.setSizes([300, 500])
        split.addWidget(side)
        split.setStretchFactor(0, 3)
        split.setStretchFactor(1, 1)
        split.setSizes([900, 340])
        self.setCentralWidget(split)
        self.resize(1280, 800)
        self.status_label = self.statusBar()

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
        return scroll

    # ------------------------------------------------------------------ the source
    def set_source(self, source) -> None:
        """Use ``source`` (started here if it is not): frames are polled from now on."""
        self.session.set_source(source)

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
        if self.session is not None:
            self.session.close_source()

    def _on_source(self, event) -> None:
        if event.value is None:
            self.timer.stop()
        else:
            self._source_started(event.value)

    def _source_started(self, source) -> None:
        if hasattr(source, "host"):
            self.source_edit.setText(f"{source.host}:{source.port}")
        self._reset_display_counters()
        self.timer.start(POLL_MS)

    # ------------------------------------------------------------------ the frame loop
    def tick(self) -> None:
        """One poll: the session simulates what came, the views draw the newest frame (from the session's
        ``frame_processed`` event), the figures are updated (never raises)."""
        if self.session is None or self.session.source is None:
            return
        try:
            self.session.tick()
            now = time.perf_counter()
            if now - getattr(self, "_last_status", 0.0) > 0.25:
                self._last_status = now
                self._update_status()
        except Exception as exc:  # a bug or a bad frame must not take the clinic's window down
            logger.exception("live view: a frame could not be shown")
            self.show_status(f"a frame could not be shown: {exc}")

    def _on_frame(self, event) -> None:
        update = event.value
        self.stage_ms.append(self.views.draw(update, self.session))
        t_drawn = time.perf_counter()
        self.frames_drawn += 1
        self.latencies_ms.append(1e3 * (t_drawn - update.frame.arrival_s))
        self.draw_times.append(t_drawn)
        self.stage_ms[-1]["simulate"] = 1e3 * update.simulate_s
        self.stage_ms[-1]["pending"] = update.frames  # frames this tick took from the source (1: no backlog)
        self.stage_ms[-1]["tick"] = 1e3 * (t_drawn - update.started_s)
        if self.frames_drawn % 10 == 1:
            self._refresh_target_figures()

    # ------------------------------------------------------------------ the panel: the session's methods
    def take_rest_now(self) -> bool:
        """The rest from the last half second (the patient holds still when the button is pressed)."""
        return self.session.take_rest_now()

    def _on_rest(self, event) -> None:
        self.rest_label.setText(event.value)
        if self.session.simulator is not self.views._scene_sim:
            self.views.forget_tongue()  # the new rest's tongue is drawn at the next frame

    def add_static_target(self) -> None:
        """A static target at the tongue tip's position now (radius from the panel)."""
        self.session.add_static_target(self.radius_spin.value() / 1000.0)

    def add_oscillating_target(self) -> None:
        """A target oscillating between the tip's position now and 10 mm below it (frequency from the panel)."""
        self.session.add_oscillating_target(self.radius_spin.value() / 1000.0, self.frequency_spin.value())

    def add_following_target(self) -> None:
        """A target following the jaw (else a head reference) where the tip is now relative to it."""
        self.session.add_following_target(self.radius_spin.value() / 1000.0)

    def add_target(self, target) -> None:
        """Add any :class:`~tonguevis.live.targets.Target` (e.g. a ReplayTarget with its ghost)."""
        self.session.add_target(target)

    def remove_target(self) -> None:
        """Remove the target selected in the list (the last one when none is)."""
        self.session.remove_target(self.target_list.currentRow())

    def _on_targets(self, _event) -> None:
        self.views.forget_targets()
        self._refresh_targets()

    def _refresh_targets(self) -> None:
        self.target_list.clear()
        for target in self.session.targets:
            self.target_list.addItem(f"{target.name} ({target.sensor}, {1000 * target.radius:.0f} mm)")
        self._refresh_target_figures()

    def _refresh_target_figures(self) -> None:
        for j, target in enumerate(self.session.targets):
            item = self.target_list.item(j)
            if item is None:
                continue
            acc = self.session.accuracy.get(j, np.nan)
            figure = "—" if not np.isfinite(acc) else f"{acc:.0f} %"
            item.setText(f"{target.name} ({target.sensor}, {1000 * target.radius:.0f} mm): {figure}")
            item.setForeground(QColor.fromRgbF(*(float(c) for c in accuracy_colour(acc))))

    def start_sweep(self) -> bool:
        """Start recording a sweep named as in the panel (every frame from now, raw and head-corrected)."""
        return self.session.start_sweep(self.sweep_name.text())

    def stop_sweep(self):
        """Stop the sweep and save it into the profile's folder; returns the SavedSweep (None if nothing saved)."""
        saved = self.session.stop_sweep()
        self._sweep_buttons()
        return saved

    def _on_sweep(self, event) -> None:
        self.sweep_label.setText(event.value)
        self._sweep_buttons()

    def _sweep_buttons(self) -> None:
        recording = self.session.sweep is not None
        self.start_button.setEnabled(not recording)
        self.stop_button.setEnabled(recording)

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
        self.session.set_smoothing(self.smooth_spin.value() if self.smooth_check.isChecked() else 0.0)

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
        session = self.session
        if session is not None:
            if session.sweep is not None:
                self.stop_sweep()
            session.close_source()
        self._stop_following()
        for stop in self._session_stops:
            stop()
        self._session_stops = []
        self.timer.stop()
        if self.state.live_session is session:
            self.state.set_live_session(None, source=self)  # the model holds no closed session
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
    window = LiveWindow(source, LiveSession(settings, sensor_names=sensor_map, profile=profile), state=AppState())
    install_error_hook(window)
    window.show()
    return app.exec()


def live_view_screenshot(window: LiveWindow, path: str | Path) -> Path:
    """Save the whole window (3D view, midsagittal view and panel) as a PNG."""
    path = Path(path)
    window.grab().save(str(path))
    return path
