"""Sensor panel: x, y and z of every sensor over time (§6.1).

Switchable between raw position, displacement from rest, velocity and
acceleration; the productions of the syllable segmentation are shaded and
the selected sensor is drawn bold.  Click or drag to seek.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from tonguevis.appstate import AppState
from tonguevis.gui.session import SIGNAL_KINDS, Session
from tonguevis.gui.timeplot import TimePlot

SENSOR_COLOURS = ["#b8860b", "#ff69b4", "#6b8e23", "#4682b4", "#a0522d", "#2c3e50", "#7f8c8d", "#9370db"]
#: Fixed colours of the canonical sensors, so a sensor keeps its colour across recordings.
NAMED_COLOURS = {"TT": "#c0392b", "TB": "#e67e22", "TD": "#2980b9", "TBK": "#1abc9c", "TL": "#27ae60",
                 "TR": "#8e44ad", "JAW": "#555555"}
AXIS_NAMES = ("x (anterior)", "y (left)", "z (up)")


class SensorPlot(TimePlot):
    def __init__(self, state: AppState, parent=None):
        super().__init__(state, parent, height=4.0)
        self.axes = self.figure.subplots(3, 1, sharex=True)
        self.lines: dict[str, list] = {}
        self.set_time_axes(list(self.axes))
        state.subscribe("selection", lambda e: self._highlight())

    def show_signals(self, times: np.ndarray, signals: dict[str, np.ndarray], label: str, unit: str,
                     productions: list[tuple[float, float]]) -> None:
        self.lines = {}
        for k, ax in enumerate(self.axes):
            ax.clear()
            ax.set_facecolor("white")
            ax.set_ylabel(f"{AXIS_NAMES[k]}\n{unit}", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(True, lw=0.3, alpha=0.5)
            for j, (start, end) in enumerate(productions):
                ax.axvspan(start, end, color="#3498db" if j % 2 else "#95a5a6", alpha=0.12, lw=0)
                ax.axvline(start, color="#7f8c8d", lw=0.6, ls="--")
            for i, (name, xyz) in enumerate(signals.items()):
                colour = NAMED_COLOURS.get(name, SENSOR_COLOURS[i % len(SENSOR_COLOURS)])
                (line,) = ax.plot(times, xyz[:, k], lw=0.9, color=colour, label=name)
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
        layout.addWidget(self.plot, 1)
        self.kind.currentIndexChanged.connect(lambda _i: self.refresh())
        self.sensor.currentIndexChanged.connect(lambda _i: state.select(self.sensor.currentData(), source=self))
        state.subscribe("selection", self._on_selection)

    @property
    def cursor_time(self) -> float:
        return self.plot.cursor_time

    def set_kind(self, kind: str) -> None:
        self.kind.setCurrentIndex(list(SIGNAL_KINDS).index(kind))

    def set_session(self, session: Session | None) -> None:
        self.session = session
        self.sensor.blockSignals(True)
        self.sensor.clear()
        self.sensor.addItem("all sensors", None)
        if session is not None:
            for name in session.signals("position"):
                self.sensor.addItem(name, name)
        self.sensor.blockSignals(False)
        self.refresh()

    def refresh(self) -> None:
        if self.session is None:
            return
        kind = self.kind.currentData()
        label, unit, _ = SIGNAL_KINDS[kind]
        self.plot.show_signals(self.session.recording.times, self.session.signals(kind), label, unit,
                               self.session.productions)

    def _on_selection(self, event) -> None:
        index = self.sensor.findData(event.value)
        if index >= 0 and index != self.sensor.currentIndex():
            self.sensor.blockSignals(True)
            self.sensor.setCurrentIndex(index)
            self.sensor.blockSignals(False)
