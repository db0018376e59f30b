"""The Palate tab: distance from the tongue's midline to the palate at the cursor, and contact over time.

Top: the distance (mm) from the tongue's dorsal midline to the palate along the
midline (mm behind the tongue tip), at the cursor's frame; 0 is contact, below
it is inside the palate.  Bottom: the motion's penetration (mm) and contact area
(mm²) over time, with the cursor (click to seek), when it was simulated against
the palate.  Distances are between the tongue and the palate, so the same in
the head and the jaw frame.  The midline plot only redraws while the tab shows.
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure
from PySide6.QtWidgets import QLabel, QSizePolicy, QVBoxLayout, QWidget

from tonguevis.appstate import AppState, connected
from tonguevis.analysis.section import MidlineProfile
from tonguevis.render.drawing import TOUCH_MM, head_points
from tonguevis.gui.timeplot import FACE, TimePlot
from tonguevis.sim.motion import frame_label

PENETRATION_COLOUR = "#c0392b"
AREA_COLOUR = "#2980b9"


class MidlinePlot(FigureCanvasQTAgg):
    """Distance to the palate (mm) along the tongue's midline (mm behind the tip) at one frame."""

    def __init__(self, parent=None):
        super().__init__(Figure(figsize=(5, 2.2), facecolor=FACE, layout="constrained"))
        self.setParent(parent)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.setMinimumHeight(150)
        self.ax = self.figure.subplots()
        self.line = None
        self.title = None

    def reset(self, position_mm: np.ndarray, top_mm: float, message: str = "", bottom_mm: float = -2.0) -> None:
        ax = self.ax
        ax.clear()
        ax.set_facecolor("white")
        ax.grid(True, lw=0.3, alpha=0.5)
        ax.tick_params(labelsize=7)
        ax.set_xlabel("position along the midline (mm behind the tongue tip, at rest)", fontsize=8)
        ax.set_ylabel("distance to the\npalate (mm)", fontsize=8)
        ax.axhspan(-100, 0, color="#ff00ff", alpha=0.08, lw=0)
        ax.axhspan(0, TOUCH_MM, color=PENETRATION_COLOUR, alpha=0.25, lw=0)
        ax.axhline(0, color="#555555", lw=0.8)
        if len(position_mm):
            ax.set_xlim(0, float(position_mm.max()) + 2)
        ax.set_ylim(bottom_mm, top_mm)
        (self.line,) = ax.plot(position_mm, np.full(len(position_mm), np.nan), "-o", ms=3, lw=1.4,
                               color="#8e44ad")
        self.title = ax.set_title(message, fontsize=8, loc="left")
        ax.text(0.99, 0.02, "0 = contact; below: inside the palate", transform=ax.transAxes, fontsize=7,
                ha="right", va="bottom", color="#555555")
        self.draw_idle()

    def show_distances(self, distances_mm: np.ndarray, title: str) -> None:
        if self.line is None:
            return
        self.line.set_ydata(distances_mm)
        self.title.set_text(title)
        self.draw_idle()


class ContactTimePlot(TimePlot):
    """Penetration (mm) and contact area (mm²) over time, with the cursor."""

    def __init__(self, state: AppState, parent=None):
        super().__init__(state, parent, height=1.8)
        self.ax = self.figure.subplots()
        self.set_time_axes([self.ax])

    def show_motion(self, times, penetration_mm, area_mm2, message: str = "") -> None:
        ax = self.ax
        for other in list(self.figure.axes):
            if other is not ax:
                other.remove()
        ax.clear()
        ax.set_facecolor("white")
        ax.tick_params(labelsize=7)
        ax.grid(True, lw=0.3, alpha=0.5)
        ax.set_xlabel("time (s)", fontsize=8)
        if len(times):
            ax.set_xlim(times[0], times[-1])
        if penetration_mm is None:
            ax.set_yticks([])
            ax.text(0.5, 0.5, message, transform=ax.transAxes, ha="center", va="center", fontsize=8, wrap=True)
        else:
            ax.plot(times, penetration_mm, color=PENETRATION_COLOUR, lw=1.0)
            ax.set_ylabel("penetration\n(mm)", fontsize=8, color=PENETRATION_COLOUR)
            ax.set_ylim(0, max(0.5, 1.2 * float(np.nanmax(penetration_mm)) if len(penetration_mm) else 0.5))
            right = ax.twinx()
            right.fill_between(times, area_mm2, color=AREA_COLOUR, alpha=0.25, lw=0)
            right.set_ylabel("contact area\n(mm²)", fontsize=8, color=AREA_COLOUR)
            right.tick_params(labelsize=7)
            right.set_ylim(0, max(10.0, 1.2 * float(np.nanmax(area_mm2)) if len(area_mm2) else 10.0))
        self.set_time_axes([ax])
        self.draw_idle()


class PalatePanel(QWidget):
    """The Palate tab (see the module doc).  ``shown_frame``: the frame the midline plot shows."""

    def __init__(self, state: AppState, parent=None):
        super().__init__(parent)
        self.state = state
        self.session = None
        self.profile: MidlineProfile | None = None
        self.shown_frame = -1
        self.header = QLabel("Open a recording: the distance from the tongue to the palate shows here.")
        self.header.setWordWrap(True)
        self.midline = MidlinePlot(self)
        self.timeline = ContactTimePlot(state, self)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addWidget(self.header)
        layout.addWidget(self.midline, 3)
        layout.addWidget(self.timeline, 2)
        connected(state.events.time, lambda event: self.show_time(event.value))

    @property
    def cursor_time(self) -> float:
        return self.timeline.cursor_time

    def set_session(self, session) -> None:
        self.session = session
        self.shown_frame = -1
        frames = getattr(session, "frames", None)
        palate = getattr(session, "shown_palate", None)
        if frames is None or palate is None:
            self.profile = None
            self.header.setText("simulating…" if frames is None and session is not None else
                                "No palate to measure against (no palate surface shipped or loaded).")
            self.midline.reset(np.zeros(0), 10.0)
            return
        motion = frames.motion
        self.profile = MidlineProfile(motion.model)
        # The range of every frame's curve, not the rest frame's: the tongue enters the palate and drops
        # far below it (on the real /ta/ -3.5 to 18 mm against the rest's -2 to 12).
        low, high = self.profile.distance_range(palate, motion)
        if not np.isfinite(low):
            low, high = 0.0, 10.0
        margin = 0.05 * max(high - low, 1.0)
        bottom, top = min(-2.0, low - margin), max(10.0, high + margin)
        self.header.setText(
            f"{palate.describe()}. Distances are from the tongue's dorsal midline (nodes within "
            f"{self.profile.band_mm:.0f} mm of its mid-plane) to the palate; the same in the head and the jaw frame.")
        self.midline.reset(self.profile.position_mm, top, bottom_mm=bottom)
        if motion.penetration is not None:
            area = motion.contact_area if motion.contact_area is not None else np.zeros(motion.n_frames)
            self.timeline.show_motion(motion.times, 1e3 * motion.penetration, 1e6 * area)
        else:
            self.timeline.show_motion(motion.times, None, None,
                                      "simulated without contact: File ▸ Load palate… (or the generic palate) "
                                      "keeps the tongue below it and reports penetration and contact area here")
        self.show_time(self.state.time, force=True)

    def show_time(self, t: float, force: bool = False) -> None:
        frames = getattr(self.session, "frames", None)
        if frames is None or self.profile is None or not (force or self.isVisible()):
            return
        i = frames.frame_at(t)
        if i == self.shown_frame and not force:
            return
        self.shown_frame = i
        d = self.profile.distances(self.session.shown_palate, head_points(frames, i))
        closest = np.nanmin(d) if np.isfinite(d).any() else float("nan")
        self.midline.show_distances(d, f"t = {frames.times[i]:.3f} s ({frame_label(i, frames.n_frames)}): closest {closest:.1f} mm")

    def showEvent(self, event) -> None:  # noqa: N802 (Qt name)
        super().showEvent(event)
        self.show_time(self.state.time, force=True)

    def close_plot(self) -> None:
        self.timeline.close_plot()
