"""The modal displacement q(t): a 3D surface (mode index × time × amplitude) with a
colour map (§6.1), and beneath it the same data as a map where a click seeks."""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure
from PySide6.QtWidgets import QSplitter, QVBoxLayout, QWidget
from PySide6.QtCore import Qt

from tonguevis.appstate import AppState
from tonguevis.gui.timeplot import FACE, TimePlot

#: Frames and modes drawn in the 3D surface (it is a picture, not a table).
SURFACE_MAX_FRAMES = 300
SURFACE_MAX_MODES = 20
#: Columns of the map below it (a long recording's frames averaged in blocks; a short one's all shown).
MAP_MAX_FRAMES = 4000
COLORMAP = "RdBu_r"


def decimate(times: np.ndarray, q: np.ndarray, max_frames: int, max_modes: int):
    """Means over blocks of k frames so at most ``max_frames`` remain (averaging, not
    picking every k-th frame, so fast oscillations do not alias), first ``max_modes`` modes."""
    step = max(1, int(np.ceil(len(times) / max_frames)))
    usable = (len(times) // step) * step
    if usable == 0:
        return times, q[:, :max_modes]
    blocks = q[:usable, :max_modes].reshape(usable // step, step, -1).mean(axis=1)
    return times[:usable].reshape(-1, step).mean(axis=1), blocks


class ModalMap(TimePlot):
    def __init__(self, state: AppState, parent=None):
        super().__init__(state, parent, height=1.6)
        self.ax = self.figure.subplots()
        self.set_time_axes([self.ax])

    def show_q(self, times: np.ndarray, q: np.ndarray) -> None:
        """Each mode's row scaled by its own largest |q| (higher modes are orders of magnitude
        smaller; unscaled, only the first few would show)."""
        self.ax.clear()
        peak = np.abs(q).max(axis=0)
        peak[peak == 0] = 1.0
        self.ax.imshow((q / peak).T, origin="lower", aspect="auto", cmap=COLORMAP, vmin=-1, vmax=1,
                       extent=(times[0], times[-1], 0.5, q.shape[1] + 0.5), interpolation="nearest")
        self.ax.set_ylabel("mode", fontsize=8)
        self.ax.set_title("q(t) per mode, scaled to each mode's largest |q|", fontsize=8)
        self.ax.set_xlabel("time (s)", fontsize=8)
        self.ax.tick_params(labelsize=7)
        self.set_time_axes([self.ax])
        self.draw_idle()


class ModalTab(QWidget):
    def __init__(self, state: AppState, parent=None):
        super().__init__(parent)
        self.state = state
        # Fixed margins, not constrained layout: a 3D axes' labels keep the positions of its previous
        # drawing until it is drawn again, so after ax3d.clear() and a new surface the layout measured
        # them thousands of pixels off and matplotlib warned "axes sizes collapsed to zero" on every run.
        self.surface_canvas = FigureCanvasQTAgg(Figure(figsize=(5, 3.5), facecolor=FACE))
        self.surface_canvas.figure.subplots_adjust(left=0.02, right=0.95, bottom=0.02, top=0.92)
        self.surface_canvas.setMinimumHeight(160)
        self.ax3d = self.surface_canvas.figure.add_subplot(projection="3d")
        self.map = ModalMap(state, self)
        splitter = QSplitter(Qt.Orientation.Vertical)
        splitter.addWidget(self.surface_canvas)
        splitter.addWidget(self.map)
        splitter.setSizes([400, 160])
        layout = QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addWidget(splitter)

    @property
    def cursor_time(self) -> float:
        return self.map.cursor_time

    def set_session(self, session) -> None:
        motion = getattr(session, "motion", None)
        self.ax3d.clear()
        if motion is None:
            self.surface_canvas.draw_idle()
            return
        scale = 1e3  # q in mm·kg^½ reads better than m·kg^½
        times, q = decimate(np.asarray(motion.times), np.asarray(motion.q), SURFACE_MAX_FRAMES, SURFACE_MAX_MODES)
        q = q * scale
        modes = np.arange(1, q.shape[1] + 1)
        T, M = np.meshgrid(times, modes, indexing="ij")
        # A few short spikes would flatten everything else: clip at the 97th percentile of |q|.
        limit = float(np.percentile(np.abs(q), 97)) or 1.0
        shown = np.clip(q, -limit, limit)
        self.ax3d.plot_surface(M, T, shown, cmap=COLORMAP, vmin=-limit, vmax=limit, linewidth=0,
                               antialiased=False, rcount=len(modes), ccount=len(times))
        self.ax3d.set_zlim(-limit, limit)
        self.ax3d.set_xlabel("mode index", fontsize=8)
        self.ax3d.set_ylabel("time (s)", fontsize=8)
        self.ax3d.set_zlabel("q (mm·kg$^{1/2}$)", fontsize=8)
        self.ax3d.tick_params(labelsize=7)
        self.ax3d.set_title(f"modal displacement q(t), first {q.shape[1]} of {motion.q.shape[1]} modes "
                            f"(clipped at ±{limit:.2g})", fontsize=9)
        self.surface_canvas.draw_idle()
        times, q = decimate(np.asarray(motion.times), np.asarray(motion.q), MAP_MAX_FRAMES, motion.q.shape[1])
        self.map.show_q(times, q * scale)
