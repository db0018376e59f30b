"""The Morph tab: morph one simulated shape into another without occlusion (§6.4, Figs. 15-16).

Pick the source and target frames by recording and time (or send them from
the Energy tab), then drag the blend slider or press Play: the tongue morphs
with q(t) = (1 − t) q_source + t q_target, **t = 0 is the source, t = 1 the
target**, warped in direct form.  Elements are coloured by the percentile
(empirical CDF) of their source–target difference, eq. (14): blue = the two
shapes agree there, red = they differ most.  The main view and the three small
views (top, front, lateral) share the same dataset, updated in place.

With an app model the tab follows its ``motions`` (the recordings the ends can come
from) and its ``morph_ends`` (an end picked elsewhere, e.g. in the Energy tab).
"""

from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtWidgets

from tonguevis.analysis.morph import Morph, morph_between
from tonguevis.render.morph import COLORMAP, bar_args, morph_bounds, morph_surface, place_camera
from tonguevis.errors import TonguevisError
from tonguevis.appstate import connected

SLIDER_STEPS = 200
PLAY_STEPS = 60  # frames from source to target while playing
PLAY_INTERVAL_MS = 33


class MorphTab(QtWidgets.QWidget):
    """Morph between frames of the motions given to :meth:`set_motions` (name -> Motion), or of the
    app model's ``motions`` when it has one."""

    blendChanged = QtCore.Signal(float)

    def __init__(self, state=None, parent=None, plotter=None):
        super().__init__(parent)
        self.state = state
        self.motions: dict = {}
        self.morph: Morph | None = None
        self.surface = None
        self._rest = None
        self._point_ids = None
        self._direction = 1
        self.t = 0.0

        self.source_file, self.target_file = QtWidgets.QComboBox(), QtWidgets.QComboBox()
        self.source_time, self.target_time = QtWidgets.QDoubleSpinBox(), QtWidgets.QDoubleSpinBox()
        for box in (self.source_time, self.target_time):
            box.setDecimals(2)
            box.setSingleStep(0.01)
            box.setSuffix(" s")
        self.source_file.currentIndexChanged.connect(lambda _i: self._limit_time(self.source_file, self.source_time))
        self.target_file.currentIndexChanged.connect(lambda _i: self._limit_time(self.target_file, self.target_time))
        self.difference = QtWidgets.QComboBox()
        self.difference.addItem("eq. (14): ‖Δũ_E‖² / V_E", "eq14")
        self.difference.addItem("mean node distance² (size-independent)", "node_mean")
        self.difference.setToolTip("what the colours rank: the paper's eq. (14) divides by the element's volume, "
                                   "so small elements stand out; the node mean does not")
        self.difference.currentIndexChanged.connect(lambda _i: self.morph is not None and self.build())
        self.build_button = QtWidgets.QPushButton("Morph")
        self.build_button.clicked.connect(self.build)
        self.slider = QtWidgets.QSlider(QtCore.Qt.Horizontal)
        self.slider.setRange(0, SLIDER_STEPS)
        self.slider.valueChanged.connect(lambda v: self.set_blend(v / SLIDER_STEPS, from_slider=True))
        self.play_button = QtWidgets.QPushButton("Play")
        self.play_button.setCheckable(True)
        self.play_button.toggled.connect(self.set_playing)
        self.timer = QtCore.QTimer(self)
        self.timer.setInterval(PLAY_INTERVAL_MS)
        self.timer.timeout.connect(self._tick)
        self.blend_label = QtWidgets.QLabel()
        self.legend_label = QtWidgets.QLabel()
        self.legend_label.setWordWrap(True)
        self.status = QtWidgets.QLabel("Choose a source and a target frame, then press Morph.")
        self.status.setWordWrap(True)

        form = QtWidgets.QGridLayout()
        form.addWidget(QtWidgets.QLabel("source (t = 0)"), 0, 0)
        form.addWidget(self.source_file, 0, 1)
        form.addWidget(self.source_time, 0, 2)
        form.addWidget(QtWidgets.QLabel("target (t = 1)"), 1, 0)
        form.addWidget(self.target_file, 1, 1)
        form.addWidget(self.target_time, 1, 2)
        form.addWidget(QtWidgets.QLabel("colour by"), 2, 0)
        form.addWidget(self.difference, 2, 1, 1, 2)
        form.addWidget(self.build_button, 0, 3, 3, 1)
        blend = QtWidgets.QHBoxLayout()
        blend.addWidget(QtWidgets.QLabel("source"))
        blend.addWidget(self.slider, 1)
        blend.addWidget(QtWidgets.QLabel("target"))
        blend.addWidget(self.play_button)

        if plotter is None:
            from tonguevis.gui.view3d import make_plotter

            plotter = make_plotter(self, shape="1|3", border=False)
        self.plotter = plotter
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(form)
        if isinstance(plotter, QtWidgets.QWidget):
            layout.addWidget(plotter, 1)
        layout.addLayout(blend)
        layout.addWidget(self.blend_label)
        layout.addWidget(self.legend_label)
        layout.addWidget(self.status)
        self._update_label()
        self._subscriptions = []
        if state is not None:
            self._subscriptions = [connected(state.events.motions, lambda event: self.set_motions(event.value)),
                                   connected(state.events.morph_ends, lambda event: self.set_end(event.key, *event.value))]
            if state.motions:
                self.set_motions(state.motions)

    # ------------------------------------------------------------------ inputs
    def set_motions(self, motions: dict) -> None:
        """Recordings (name -> Motion, all on one model) the ends can come from."""
        self.motions = dict(motions)
        for box in (self.source_file, self.target_file):
            current = box.currentText()
            box.blockSignals(True)
            box.clear()
            box.addItems(list(self.motions))
            if current in self.motions:
                box.setCurrentText(current)
            box.blockSignals(False)
        self._limit_time(self.source_file, self.source_time)
        self._limit_time(self.target_file, self.target_time)

    def _limit_time(self, box, spin) -> None:
        motion = self.motions.get(box.currentText())
        if motion is not None:
            spin.setRange(float(motion.times[0]), float(motion.times[-1]))

    def set_end(self, which: str, recording: str, time: float, build: bool = True) -> None:
        """Set the source or target frame (e.g. from the Energy tab); morphs when both are set."""
        if recording not in self.motions:
            self.status.setText(f"{recording} has not been simulated in this session; add its motion first.")
            return
        box, spin = (self.source_file, self.source_time) if which == "source" else (self.target_file, self.target_time)
        box.setCurrentText(recording)
        self._limit_time(box, spin)
        spin.setValue(time)
        if build:
            self.build()

    # ------------------------------------------------------------------ morph
    def build(self) -> None:
        """Build the morph of the chosen ends and show it at t = 0 (the source)."""
        src, tgt = self.motions.get(self.source_file.currentText()), self.motions.get(self.target_file.currentText())
        if src is None or tgt is None:
            self.status.setText("Choose both a source and a target recording.")
            return
        try:
            morph = morph_between(src, self.source_time.value(), tgt, self.target_time.value(),
                                  difference=self.difference.currentData())
        except TonguevisError as exc:
            self.status.setText(f"Cannot morph: {exc}")
            return
        morph.labels = (f"{self.source_file.currentText()} @ {src.times[morph.source_frame]:.2f} s",
                        f"{self.target_file.currentText()} @ {tgt.times[morph.target_frame]:.2f} s")
        self.morph = morph
        self._build_scene()
        diff = morph.element_difference
        quantiles = morph.colour_legend((0.0, 0.25, 0.5, 0.75, 1.0))
        what = ("e = ‖ũ_src − ũ_tgt‖²/V (eq. 14)" if morph.difference == "eq14"
                else "e = mean over its nodes of |ũ_src − ũ_tgt|²")
        self.legend_label.setText(
            f"Colour = percentile of the element's source–target difference {what}, "
            "blue = alike, red = most different; percentiles → e: "
            + ", ".join(f"{int(100 * p)}% → {v:.3g} {morph.difference_unit}" for p, v in quantiles))
        gap = 1e3 * np.linalg.norm(morph.source_displacement - morph.target_displacement, axis=1)
        self.status.setText(f"Morph {morph.labels[0]} → {morph.labels[1]}: nodes move up to {gap.max():.1f} mm "
                            f"(mean {gap.mean():.1f} mm); median element difference {np.median(diff):.3g} {morph.difference_unit}.")
        self.slider.blockSignals(True)
        self.slider.setValue(0)
        self.slider.blockSignals(False)
        self.set_blend(0.0)

    def _build_scene(self) -> None:
        plotter, morph = self.plotter, self.morph
        plotter.clear()
        self.surface = morph_surface(morph)
        self._point_ids = np.asarray(self.surface.point_data["vtkOriginalPointIds"])
        self._rest = morph.model.mesh.points[self._point_ids]
        centre, radius = morph_bounds(morph, np.linspace(0, 1, 5))
        for k, view in enumerate(("oblique", "top", "front", "lateral")):
            plotter.subplot(k)
            plotter.add_mesh(self.surface, scalars="difference", cmap=COLORMAP, clim=(0, 1), show_scalar_bar=(k == 0),
                             scalar_bar_args=bar_args(morph))
            plotter.add_text(f"{view} · jaw frame" if k == 0 else view, font_size=8, position="upper_left")
            place_camera(plotter, view, centre, radius, zoom=1.3)
        plotter.subplot(0)

    def set_blend(self, t: float, from_slider: bool = False) -> None:
        """Show the blend at t in [0, 1] (0 = source, 1 = target): points updated in place, one render."""
        self.t = min(max(float(t), 0.0), 1.0)
        if not from_slider:
            self.slider.blockSignals(True)
            self.slider.setValue(round(self.t * SLIDER_STEPS))
            self.slider.blockSignals(False)
        if self.morph is not None and self.surface is not None:
            disp = self.morph.displacement(self.t)
            self.surface.points[:] = self._rest + disp[self._point_ids]
            self.plotter.render()
        self._update_label()
        self.blendChanged.emit(self.t)

    def displayed_points(self) -> np.ndarray | None:
        """(n_surface, 3) surface points shown now, with their mesh node ids in ``surface_node_ids``."""
        return None if self.surface is None else np.asarray(self.surface.points)

    @property
    def surface_node_ids(self) -> np.ndarray | None:
        return self._point_ids

    def _update_label(self) -> None:
        if self.morph is None:
            self.blend_label.setText("q(t) = (1 − t) q_source + t q_target; t = 0 is the source, t = 1 the target.")
        else:
            self.blend_label.setText(f"t = {self.t:.2f}   (t = 0: source {self.morph.labels[0]};  "
                                     f"t = 1: target {self.morph.labels[1]})")

    # ------------------------------------------------------------------ playback
    def set_playing(self, playing: bool) -> None:
        """Play the morph forward and back until stopped."""
        if self.play_button.isChecked() != playing:
            self.play_button.setChecked(playing)  # re-enters through toggled
            return
        self.play_button.setText("Pause" if playing else "Play")
        if playing and self.morph is not None:
            self.timer.start()
        else:
            self.timer.stop()

    def _tick(self) -> None:
        t = self.t + self._direction / PLAY_STEPS
        if t >= 1.0 or t <= 0.0:
            t = min(max(t, 0.0), 1.0)
            self._direction = -self._direction
        self.set_blend(t)

    def closeEvent(self, event) -> None:  # noqa: N802 (Qt name)
        for unsubscribe in self._subscriptions:
            unsubscribe()
        self._subscriptions = []
        self.timer.stop()
        if hasattr(self.plotter, "close"):
            self.plotter.close()
        super().closeEvent(event)
