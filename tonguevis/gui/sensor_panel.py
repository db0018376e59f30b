"""Sensor panel: x, y and z of the tongue sensors over time (§6.1).

Switchable between raw position, displacement from rest, velocity and
acceleration; the productions of the syllable segmentation are shaded, their
gesture landmarks marked on the articulator's vertical trace, and the selected
sensor is drawn bold.  With "edit productions" on, dragging a production's
boundary moves it and the buttons add a production at the cursor, delete the one
under it, and save them beside the recording (a TextGrid every command then uses).  Head references, the jaw and channels
the sensor map leaves unnamed are hidden unless asked for: a reference
120 mm away would flatten the tongue's traces, since each axis scales to
what it shows.  Click or drag to seek.
"""

from __future__ import annotations

from itertools import cycle

import numpy as np
from PySide6.QtCore import Signal
from PySide6.QtWidgets import QCheckBox, QComboBox, QLabel, QPushButton, QVBoxLayout, QWidget

from tonguevis.gui.flow_layout import FlowLayout
from tonguevis.appstate import AppState, connected
from tonguevis.errors import TonguevisError
from tonguevis.workflows.session import SIGNAL_KINDS, Session, tongue_sensors
from tonguevis.gui.timeplot import TimePlot
from tonguevis.render.production_marks import mark_landmarks, shade_productions

SENSOR_COLOURS = ["#b8860b", "#ff69b4", "#6b8e23", "#4682b4", "#a0522d", "#2c3e50", "#7f8c8d", "#9370db"]
#: Fixed colours of the canonical sensors, so a sensor keeps its colour across recordings.
NAMED_COLOURS = {"TT": "#c0392b", "TB": "#e67e22", "TD": "#2980b9", "TBK": "#1abc9c", "TL": "#27ae60",
                 "TR": "#8e44ad", "JAW": "#555555"}
AXIS_NAMES = ("x (anterior)", "y (left)", "z (up)")
OTHERS_LABEL = "show reference and other channels"
#: Past this many samples a trace is drawn as its lowest and highest value in each of
#: TRACE_BINS bins: the panel always shows the whole recording, a few hundred pixels wide, so
#: the picture is the same; matplotlib kept four copies of every sample (30 minutes: 70 MB).
MAX_TRACE_POINTS = 20000
TRACE_BINS = 5000


def envelope_trace(times: np.ndarray, values: np.ndarray, bins: int = TRACE_BINS) -> tuple[np.ndarray, np.ndarray]:
    """(times, values) of a trace drawn as its lowest and highest value in each of ``bins`` bins
    (two points a bin, at its first and last sample time; a bin with no valid value is a gap, NaN);
    the samples themselves when there are at most 2 ``bins`` of them.  times (N,) s, values (N,)."""
    n = len(times)
    if n <= 2 * bins:
        return times, values
    edges = np.linspace(0, n, bins + 1).astype(np.int64)
    low = np.fmin.reduceat(values, edges[:-1])  # fmin/fmax skip NaN; a bin of NaN only stays NaN
    high = np.fmax.reduceat(values, edges[:-1])
    t = np.column_stack([times[edges[:-1]], times[edges[1:] - 1]]).ravel()
    return t, np.column_stack([low, high]).ravel()


def sensor_colours(names) -> dict[str, str]:
    """{name: colour}: the canonical sensors' own, the palette in turn for the other channels."""
    others = cycle(SENSOR_COLOURS)
    return {name: NAMED_COLOURS.get(name) or next(others) for name in names}


#: A press this close (pixels) to a production's boundary grabs it while editing.
GRAB_PIXELS = 6


class SensorPlot(TimePlot):
    #: (production index, "start" or "end", time_s): a boundary was dragged there while editing
    boundary_moved = Signal(int, str, float)

    def __init__(self, state: AppState, parent=None):
        super().__init__(state, parent, height=4.0)
        self.axes = self.figure.subplots(3, 1, sharex=True)
        self.lines: dict[str, list] = {}
        self.productions: list[tuple[float, float]] = []
        self.editing = False
        self._grabbed: tuple[int, str] | None = None
        self.set_time_axes(list(self.axes))
        connected(state.events.selection, lambda e: self._highlight())

    def show_signals(self, times: np.ndarray, signals: dict[str, np.ndarray], label: str, unit: str,
                     productions: list[tuple[float, float]], colours: dict[str, str] | None = None,
                     landmarks=(), articulator: str | None = None) -> None:
        """Plot ``signals`` ({name: (N, 3)}); each axis's y range fits them (autoscaled); the
        productions shaded and their ``landmarks`` (GestureLandmarks) on ``articulator``'s z trace."""
        self.productions = [tuple(map(float, p)) for p in productions]
        self.lines = {}
        colours = colours or sensor_colours(list(signals))
        for k, ax in enumerate(self.axes):
            ax.clear()
            ax.set_facecolor("white")
            ax.set_ylabel(f"{AXIS_NAMES[k]}\n{unit}", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(True, lw=0.3, alpha=0.5)
            shade_productions(ax, productions)
            for name, xyz in signals.items():
                t, v = envelope_trace(times, xyz[:, k]) if len(times) > MAX_TRACE_POINTS else (times, xyz[:, k])
                (line,) = ax.plot(t, v, lw=0.9, color=colours[name], label=name)
                self.lines.setdefault(name, []).append(line)
        if landmarks and articulator in signals:  # where the constriction is: the vertical trace
            mark_landmarks(self.axes[2], landmarks, times, signals[articulator][:, 2], legend=True)
        elif landmarks:
            mark_landmarks(self.axes[2], landmarks, legend=True)
        if len(times):
            self.axes[0].set_xlim(times[0], times[-1])
        self.axes[-1].set_xlabel("time (s)", fontsize=8)
        if signals:  # above the plots, where it hides no data
            self.axes[0].legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), fontsize=7, ncol=min(len(signals), 8),
                                frameon=False, borderaxespad=0.2, handlelength=1.5)
        self.set_time_axes(list(self.axes))
        self._highlight(draw=False)
        self.draw_idle()

    # -- editing the productions' boundaries ------------------------------------------
    def boundary_near(self, event) -> tuple[int, str] | None:
        """(index, "start"/"end") of the production boundary within GRAB_PIXELS of a mouse event."""
        if event.inaxes not in self._time_axes or event.x is None:
            return None
        ratio = self.device_pixel_ratio or 1.0
        best, where = GRAB_PIXELS * ratio, None
        for index, (start, end) in enumerate(self.productions):
            for side, t in (("start", start), ("end", end)):
                distance = abs(event.inaxes.transData.transform((t, 0.0))[0] - event.x)
                if distance <= best:
                    best, where = distance, (index, side)
        return where

    def _on_press(self, event) -> None:
        if self.editing and event.button == 1:
            self._grabbed = self.boundary_near(event)
        super()._on_press(event)

    def _on_release(self, event) -> None:
        grabbed, self._grabbed = self._grabbed, None
        super()._on_release(event)
        if grabbed is not None and event.xdata is not None and event.inaxes in self._time_axes:
            self.boundary_moved.emit(grabbed[0], grabbed[1], float(event.xdata))

    def _highlight(self, draw: bool = True) -> None:
        selected = self.state.selection
        for name, lines in self.lines.items():
            for line in lines:
                line.set_linewidth(2.0 if name == selected else 0.9)
                line.set_alpha(1.0 if selected in (None, name) else 0.45)
        if draw:
            self.draw_idle()


class SensorPanel(QWidget):
    """The plot plus its controls (what to show, which sensor to highlight)."""

    def __init__(self, state: AppState, parent=None):
        super().__init__(parent)
        self.state = state
        self.session: Session | None = None
        self.kind = QComboBox()
        for kind, (label, unit, _) in SIGNAL_KINDS.items():
            self.kind.addItem(f"{label} ({unit})", kind)
        self.sensor = QComboBox()
        self.sensor.addItem("all sensors", None)
        self.others = QCheckBox(OTHERS_LABEL)
        self.others.setToolTip("Head references, the jaw, lips and channels the sensor map leaves unnamed;\n"
                               "hidden by default so that the axes fit the tongue's motion")
        self.plot = SensorPlot(state, self)
        self.edit = QCheckBox("edit productions")
        self.edit.setToolTip("drag a production's boundary to move it; add a production at the cursor, delete "
                             "the one under it, and save them beside the recording as a TextGrid that every "
                             "tonguevis command then uses")
        self.add_button = QPushButton("Add at cursor")
        self.delete_button = QPushButton("Delete at cursor")
        self.save_button = QPushButton("Save productions")
        self.save_button.setToolTip("write NAME.TextGrid beside the recording (its own tiers kept)")
        # Rows that wrap where the tab is narrow (1280 pixels beside the 3D views) instead of widening it.
        controls = FlowLayout()
        for widget in (QLabel("Show"), self.kind, QLabel("Highlight"), self.sensor):
            controls.addWidget(widget)
        options = FlowLayout()
        for widget in (self.others, self.edit, self.add_button, self.delete_button, self.save_button):
            options.addWidget(widget)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addLayout(controls)
        layout.addLayout(options)
        layout.addWidget(self.plot, 1)
        self.edit.toggled.connect(self._on_edit_toggled)
        self.add_button.clicked.connect(self.add_production)
        self.delete_button.clicked.connect(self.delete_production)
        self.save_button.clicked.connect(self.save_productions)
        self.plot.boundary_moved.connect(self.move_boundary)
        self._on_edit_toggled(False)
        connected(state.events.productions, self._on_productions)
        self.kind.currentIndexChanged.connect(lambda _i: self.refresh())
        self.others.toggled.connect(lambda _on: self.refresh())
        self.sensor.currentIndexChanged.connect(lambda _i: state.select(self.sensor.currentData(), source=self))
        connected(state.events.selection, self._on_selection)

    @property
    def cursor_time(self) -> float:
        return self.plot.cursor_time

    def set_kind(self, kind: str) -> None:
        self.kind.setCurrentIndex(list(SIGNAL_KINDS).index(kind))

    def set_session(self, session: Session | None) -> None:
        if session is not None and session is self.session and self.kind.currentData() != "displacement":
            # Its motion came (the app model calls again): only the displacements, from the simulation's
            # rest, change; redrawing 30 minutes of traces took a second of the GUI thread each time.
            return
        self.session = session
        self.sensor.blockSignals(True)
        self.sensor.clear()
        self.sensor.addItem("all sensors", None)
        hidden = 0
        if session is not None:
            names = list(session.signals("position"))
            for name in names:
                self.sensor.addItem(name, name)
            hidden = len(names) - len(self.shown(names))
        self.sensor.blockSignals(False)
        self.others.setText(f"{OTHERS_LABEL} ({hidden})" if hidden else OTHERS_LABEL)
        self.refresh()

    def shown(self, names) -> list[str]:
        """The channels plotted: the tongue sensors, all of them when asked or when there is none."""
        tongue = tongue_sensors(names)
        return list(names) if self.others.isChecked() or not tongue else tongue

    def set_show_others(self, on: bool) -> None:
        self.others.setChecked(on)

    def refresh(self) -> None:
        if self.session is None:
            return
        kind = self.kind.currentData()
        label, unit, _ = SIGNAL_KINDS[kind]
        signals = self.session.signals(kind)
        colours = sensor_colours(list(signals))  # of every channel: the same whether the others show or not
        shown = {name: signals[name] for name in self.shown(signals)}
        table = self.session.production_table
        self.plot.show_signals(self.session.recording.times, shown, label, unit, self.session.productions, colours,
                               landmarks=list(getattr(table, "landmarks", []) or []),
                               articulator=getattr(table, "articulator", None))
        self._update_edit_buttons()

    # -- corrections of the productions ----------------------------------------------
    def _on_edit_toggled(self, on: bool) -> None:
        self.plot.editing = on
        self._update_edit_buttons()

    def _update_edit_buttons(self) -> None:
        editor = self.session.production_editor if self.session is not None else None
        on = self.edit.isChecked() and self.session is not None
        self.add_button.setEnabled(on)
        self.delete_button.setEnabled(on and editor is not None and len(editor.table) > 0)
        self.save_button.setEnabled(editor is not None and editor.edited)

    def _editor(self):
        """The session's production editor; one with no production when none were found."""
        from tonguevis.preprocess.productions import ProductionTable

        if self.session.production_table is None:
            self.session.set_production_table(ProductionTable())
        return self.session.production_editor

    def _apply(self, change, what: str) -> bool:
        """Run ``change(editor)``; announce the new table, or show why it could not be done."""
        from tonguevis.gui.dialogs import error_box

        if self.session is None:
            return False
        editor = self._editor()
        try:
            table = change(editor)
        except (TonguevisError, IndexError) as exc:
            self.last_dialog = error_box(self, f"Cannot {what}", str(exc), self.session.path)
            self.state.set_status(f"Cannot {what}: {exc}", self)
            return False
        self.state.set_productions(self.session, table, self)
        self.state.set_status(f"{what}: {len(table)} productions (not saved: Save productions writes them)", self)
        return True

    def move_boundary(self, index: int, side: str, time: float) -> bool:
        return self._apply(lambda e: e.move_boundary(index, side, time), f"move the {side} of production {index + 1}")

    def add_production(self) -> bool:
        return self._apply(lambda e: e.add(self.state.time), f"add a production at {self.state.time:.3f} s")

    def delete_production(self) -> bool:
        editor = self._editor()
        index = editor.index_at(self.state.time)
        if index is None:
            self.state.set_status(f"no production at {self.state.time:.3f} s to delete", self)
            return False
        return self._apply(lambda e: e.delete(index), f"delete production {index + 1}")

    def save_productions(self, path=None) -> bool:
        """Write the productions beside the recording (or to ``path``); a dialog on failure."""
        from tonguevis.gui.dialogs import error_box

        if self.session is None or self.session.production_editor is None:
            return False
        editor = self.session.production_editor
        try:
            written = editor.save(path)
        except (TonguevisError, OSError) as exc:
            self.last_dialog = error_box(self, "Cannot save productions", str(exc), self.session.path)
            return False
        self.state.set_status(f"saved {len(editor.table)} productions to {written} (every tonguevis command now "
                              "uses them)", self)
        self._update_edit_buttons()
        return True

    def _on_productions(self, event) -> None:
        if event.key == "primary" and event.value is self.session:
            self.refresh()

    def _on_selection(self, event) -> None:
        index = self.sensor.findData(event.value)
        if index >= 0 and index != self.sensor.currentIndex():
            self.sensor.blockSignals(True)
            self.sensor.setCurrentIndex(index)
            self.sensor.blockSignals(False)
