"""Transport bar: play/pause, step, speed, loop the current production, timeline slider."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QCheckBox, QComboBox, QHBoxLayout, QSlider, QToolButton, QWidget

from tonguevis.appstate import AppState, connected, interval_at
from tonguevis.gui.elastic_label import ElasticLabel
from tonguevis.sim.motion import frame_label

SPEEDS = (0.25, 0.5, 0.75, 1.0)


class TransportBar(QWidget):
    def __init__(self, state: AppState, parent=None):
        super().__init__(parent)
        self.state = state
        self.productions: list[tuple[float, float]] = []
        self.back = QToolButton(text="◀|", toolTip="step one frame back (Left)")
        self.play = QToolButton(text="▶", toolTip="play / pause (Space)")
        self.forward = QToolButton(text="|▶", toolTip="step one frame forward (Right)")
        self.speed = QComboBox(toolTip="playback speed (slower speeds lower the pitch, like a tape)")
        for s in SPEEDS:
            self.speed.addItem(f"{s:g}×", s)
        self.speed.setCurrentIndex(len(SPEEDS) - 1)
        self.loop = QCheckBox("loop production", toolTip="loop over the production under the cursor")
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.setRange(0, 0)
        self.label = ElasticLabel(minimum_width=190)  # "production 3/15" or not: no resize while playing
        layout = QHBoxLayout(self)
        layout.setContentsMargins(4, 2, 4, 2)
        for widget in (self.back, self.play, self.forward, self.speed, self.loop):
            layout.addWidget(widget)
        layout.addWidget(self.slider, 1)
        layout.addWidget(self.label)
        self.back.clicked.connect(lambda: state.step(-1, source=self))
        self.forward.clicked.connect(lambda: state.step(1, source=self))
        self.play.clicked.connect(lambda: state.toggle_playing(source=self))
        self.speed.currentIndexChanged.connect(lambda _i: state.set_speed(self.speed.currentData(), source=self))
        self.loop.toggled.connect(self._on_loop_toggled)
        self.slider.valueChanged.connect(self._on_slider)
        self.cursor_time = state.time
        connected(state.events.time, self._on_time)
        connected(state.events.session, lambda e: self.set_productions(e.value.productions)
                  if e.key == "primary" and e.value is not None else None)
        connected(state.events.playing, lambda e: self.play.setText("❚❚" if e.value else "▶"))
        connected(state.events.range, lambda e: self._on_range())
        connected(state.events.speed, self._on_speed)
        connected(state.events.loop, lambda e: self._on_loop_changed(e.value))
        connected(state.events.productions, lambda e: self.set_productions(e.value.productions) if e.key == "primary"
                        else None)

    def set_productions(self, productions: list[tuple[float, float]]) -> None:
        self.productions = list(productions)
        self.loop.setEnabled(bool(productions))

    def _frame(self, t: float) -> int:
        return int(round((t - self.state.start) / self.state.frame_period))

    def _on_range(self) -> None:
        self.slider.blockSignals(True)
        self.slider.setRange(0, self._frame(self.state.end))
        self.slider.blockSignals(False)

    def _on_time(self, event) -> None:
        t = event.value
        self.cursor_time = t
        self.slider.blockSignals(True)
        self.slider.setValue(self._frame(t))
        self.slider.blockSignals(False)
        production = interval_at(self.productions, t)
        where = ""
        if production is not None:
            where = f"  production {self.productions.index(production) + 1}/{len(self.productions)}"
        frame = frame_label(self._frame(t), self._frame(self.state.end) + 1)
        self.label.setText(f"{t:7.3f} s / {self.state.end:.2f} s  {frame}{where}")

    def _on_slider(self, value: int) -> None:
        self.state.set_time(self.state.start + value * self.state.frame_period, source=self)

    def _on_speed(self, event) -> None:
        index = self.speed.findData(event.value)
        if index >= 0:
            self.speed.setCurrentIndex(index)

    def _on_loop_toggled(self, on: bool) -> None:
        if not on:
            self.state.set_loop(None, source=self)
            return
        production = interval_at(self.productions, self.state.time)
        if production is None and self.productions:
            # Not inside one: the next production (or the last).
            later = [p for p in self.productions if p[0] >= self.state.time]
            production = later[0] if later else self.productions[-1]
        self.state.set_loop(production, source=self)

    def _on_loop_changed(self, loop) -> None:
        self.loop.blockSignals(True)
        self.loop.setChecked(loop is not None)
        self.loop.blockSignals(False)
