"""Sensor panel: x, y and z of the tongue sensors over time (§6.1).

Switchable between raw position, displacement from rest, velocity and
acceleration; the productions of the syllable segmentation are shaded and
the selected sensor is drawn bold.  Head references, the jaw and channels
the sensor map leaves unnamed are hidden unless asked for: a reference
120 mm away would flatten the tongue's traces, since each axis scales to
what it shows.  Click or drag to seek.
"""

from __future__ import annotations

from itertools import cycle

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QCheckBox, QComboBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from tonguevis.appstate import AppState
from tonguevis.gui.session import SIGNAL_KINDS, Session, tongue_sensors
from tonguevis.gui.timeplot import TimePlot

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


class SensorPlot(TimePlot):
    def __init__(self, state: AppState, parent=None):
        super().__init__(state, parent, height=4.0)
        self.axes = self.figure.subplots(3, 1, sharex=True)
        self.lines: dict[str, list] = {}
        self.set_time_axes(list(self.axes))
        state.subscribe("selection", lambda e: self._highlight())

    def show_signals(self, times: np.ndarray, signals: dict[str, np.ndarray], label: str, unit: str,
                     productions: list[tuple[float, float]], colours: dict[str, str] | None = None) -> None:
        """Plot ``signals`` ({name: (N, 3)}); each axis's y range fits them (autoscaled)."""
        self.lines = {}
        colours = colours or sensor_colours(list(signals))
        for k, ax in enumerate(self.axes):
            ax.clear()
            ax.set_facecolor("white")
            ax.set_ylabel(f"{AXIS_NAMES[k]}\n{unit}", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(True, lw=0.3, alpha=0.5)
            _shade_productions(ax, productions)
            for name, xyz in signals.items():
                t, v = envelope_trace(times, xyz[:, k]) if len(times) > MAX_TRACE_POINTS else (times, xyz[:, k])
                (line,) = ax.plot(t, v, lw=0.9, color=colours[name], label=name)
                self.lines.setdefault(name, []).append(line)
        if len(times):
            self.axes[0].set_xlim(times[0], times[-1])
        self.axes[-1].set_xlabel("time (s)", fontsize=8)
        if signals:  # above the plots, where it hides no data
            self.axes[0].legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), fontsize=7, ncol=min(len(signals), 8),
                                frameon=False, borderaxespad=0.2, handlelength=1.5)
        self.set_time_axes(list(self.axes))
        self._highlight(draw=False)
        self.draw_idle()

    def _highlight(self, draw: bool = True) -> None:
        selected = self.state.selection
        for name, lines in self.lines.items():
            for line in lines:
                line.set_linewidth(2.0 if name == selected else 0.9)
                line.set_alpha(1.0 if selected in (None, name) else 0.45)
        if draw:
            self.draw_idle()


def _shade_productions(ax, productions) -> None:
    """Shade each production (alternating colours) and dash its start: two artists per axes
    whatever their number (one per production made a 30-minute recording take minutes to draw)."""
    from matplotlib.collections import LineCollection, PolyCollection

    if not len(productions):
        return
    spans = np.asarray(productions, dtype=np.float64).reshape(-1, 2)
    band = ax.get_xaxis_transform()  # x in seconds, y from the bottom (0) to the top (1) of the axes
    boxes = [[(a, 0.0), (a, 1.0), (b, 1.0), (b, 0.0)] for a, b in spans]
    colours = ["#3498db" if j % 2 else "#95a5a6" for j in range(len(spans))]
    ax.add_collection(PolyCollection(boxes, facecolors=colours, alpha=0.12, linewidths=0, transform=band),
                      autolim=False)
    ax.add_collection(LineCollection([[(a, 0.0), (a, 1.0)] for a in spans[:, 0]], colors="#7f8c8d", linewidths=0.6,
                                     linestyles="--", transform=band), autolim=False)


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
        controls = QHBoxLayout()
        controls.addWidget(QLabel("Show"))
        controls.addWidget(self.kind)
        controls.addWidget(QLabel("Highlight"))
        controls.addWidget(self.sensor)
        controls.addStretch(1)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addLayout(controls)
        layout.addWidget(self.others, 0, Qt.AlignmentFlag.AlignLeft)  # own row: beside the combos it widens the tab
        layout.addWidget(self.plot, 1)
        self.kind.currentIndexChanged.connect(lambda _i: self.refresh())
        self.others.toggled.connect(lambda _on: self.refresh())
        self.sensor.currentIndexChanged.connect(lambda _i: state.select(self.sensor.currentData(), source=self))
        state.subscribe("selection", self._on_selection)

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
        self.plot.show_signals(self.session.recording.times, shown, label, unit, self.session.productions, colours)

    def _on_selection(self, event) -> None:
        index = self.sensor.findData(event.value)
        if index >= 0 and index != self.sensor.currentIndex():
            self.sensor.blockSignals(True)
            self.sensor.setCurrentIndex(index)
            self.sensor.blockSignals(False)
