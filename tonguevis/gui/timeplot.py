"""A matplotlib canvas whose x axis is time, linked to the AppState.

Every time plot (sensor panel, waveform, spectrogram, modal map) derives from
:class:`TimePlot`: clicking or dragging in one of its time axes calls
``state.set_time``; every ``time`` event moves its cursor lines.  Cursors are
drawn by blitting over a cached background, so playback costs a few
milliseconds per plot instead of a full redraw.
"""

from __future__ import annotations

from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure
from PySide6.QtWidgets import QSizePolicy

from tonguevis.appstate import AppState, Event

CURSOR_COLOUR = "#e74c3c"
FACE = "#fbfbfb"


class TimePlot(FigureCanvasQTAgg):
    """Base class: subclasses create axes in ``self.figure`` and call :meth:`set_time_axes`."""

    def __init__(self, state: AppState, parent=None, height: float = 2.0):
        super().__init__(Figure(figsize=(5, height), facecolor=FACE, layout="constrained"))
        self.setParent(parent)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.state = state
        self.cursor_time = state.time  # what the cursors show (tests compare views by it)
        self._time_axes: list = []
        self._cursors: list = []
        self._background = None
        self._dragging = False
        self._unsubscribe = [state.subscribe("time", self._on_time)]
        self.mpl_connect("draw_event", self._on_draw)
        self.mpl_connect("button_press_event", self._on_press)
        self.mpl_connect("motion_notify_event", self._on_motion)
        self.mpl_connect("button_release_event", self._on_release)

    def set_time_axes(self, axes: list) -> None:
        """Axes whose x is time (s): they get a cursor and seek on click/drag."""
        self._time_axes = list(axes)
        self._cursors = [ax.axvline(self.state.time, color=CURSOR_COLOUR, lw=1.2, animated=True)
                         for ax in self._time_axes]
        self._background = None

    def close_plot(self) -> None:
        for unsubscribe in self._unsubscribe:
            unsubscribe()
        self._unsubscribe = []

    # -- cursor ---------------------------------------------------------------
    def _on_draw(self, _event) -> None:
        self._background = self.copy_from_bbox(self.figure.bbox)
        self._draw_cursors()

    def _draw_cursors(self) -> None:
        for line in self._cursors:
            line.set_xdata([self.cursor_time, self.cursor_time])
            line.axes.draw_artist(line)

    def _on_time(self, event: Event) -> None:
        self.cursor_time = event.value
        if not self._cursors or not self.isVisible():
            return  # drawn at the right place when shown (draw_event)
        if self._background is None:
            self.draw_idle()
            return
        self.restore_region(self._background)
        self._draw_cursors()
        self.blit(self.figure.bbox)

    # -- seeking ----------------------------------------------------------------
    def _seek(self, event) -> bool:
        if event.inaxes in self._time_axes and event.xdata is not None:
            self.state.set_time(float(event.xdata), source=self)
            return True
        return False

    def _on_press(self, event) -> None:
        if event.button == 1 and self._seek(event):
            self._dragging = True

    def _on_motion(self, event) -> None:
        if self._dragging:
            self._seek(event)

    def _on_release(self, _event) -> None:
        self._dragging = False

    def data_to_widget(self, ax, t: float, y: float):
        """Widget pixel (x, y) of data point (t, y) in ``ax`` (for tests and tooltips)."""
        x_px, y_px = ax.transData.transform((t, y))
        ratio = self.device_pixel_ratio or 1.0
        return int(round(x_px / ratio)), int(round(self.height() - y_px / ratio))
