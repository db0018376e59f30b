"""A matplotlib canvas whose x axis is time, linked to the AppState.

Every time plot (sensor panel, waveform, spectrogram, modal map) derives from
:class:`TimePlot`: clicking or dragging in one of its time axes calls
``state.set_time``; every ``time`` event moves its cursor lines.  The cursors
are painted by a transparent Qt overlay from the axes' cached pixel
transforms, so moving them costs no matplotlib drawing at all (a blit of the
whole figure cost tens of milliseconds per plot per frame under software
rendering); only the two thin strips of the old and new line repaint, from a
copy of the figure's picture made once per draw (matplotlib's own paint
converts the strip from its buffer at every paint).
"""

from __future__ import annotations

from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure
import numpy as np
from PySide6.QtCore import QPoint, QRect, Qt
from PySide6.QtGui import QColor, QImage, QPainter, QPen
from PySide6.QtWidgets import QSizePolicy, QWidget

from tonguevis.appstate import AppState, Event, connected

CURSOR_COLOUR = "#e74c3c"
FACE = "#fbfbfb"


class CursorOverlay(QWidget):
    """Draws vertical cursor lines over the canvas; transparent to the mouse."""

    def __init__(self, canvas: "TimePlot"):
        super().__init__(canvas)
        self.canvas = canvas
        self.setAttribute(Qt.WidgetAttribute.WA_TransparentForMouseEvents)
        self.setAttribute(Qt.WidgetAttribute.WA_NoSystemBackground)
        self.columns: list[tuple[int, int, int]] = []  # (x, top, bottom) in widget pixels

    def paintEvent(self, _event) -> None:  # noqa: N802 (Qt name)
        if not self.columns:
            return
        painter = QPainter(self)
        painter.setPen(QPen(QColor(CURSOR_COLOUR), 1.5))
        for x, top, bottom in self.columns:
            painter.drawLine(x, top, x, bottom)
        painter.end()

    def set_columns(self, columns: list[tuple[int, int, int]]) -> None:
        old = self.columns
        self.columns = columns
        for x, top, bottom in old + columns:
            self.update(QRect(x - 2, top, 5, bottom - top + 1))


class TimePlot(FigureCanvasQTAgg):
    """Base class: subclasses create axes in ``self.figure`` and call :meth:`set_time_axes`."""

    def __init__(self, state: AppState, parent=None, height: float = 2.0):
        super().__init__(Figure(figsize=(5, height), facecolor=FACE, layout="constrained"))
        self.setParent(parent)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.setMinimumHeight(110)  # below this the axes' labels leave no room to plot
        self.state = state
        self.cursor_time = state.time  # what the cursors show (tests compare views by it)
        self.overlay = CursorOverlay(self)
        self._time_axes: list = []
        self._drawn = False  # axes transforms valid (set after a draw)
        self._columns: list = []  # the time axes' pixel geometry at the last draw (see _axis_columns)
        self._picture: QImage | None = None  # the figure as drawn last, in the screen's pixel format
        self._dragging = False
        self._unsubscribe = [connected(state.events.time, self._on_time)]
        self.mpl_connect("draw_event", self._on_draw)
        self.mpl_connect("button_press_event", self._on_press)
        self.mpl_connect("motion_notify_event", self._on_motion)
        self.mpl_connect("button_release_event", self._on_release)

    def set_time_axes(self, axes: list) -> None:
        """Axes whose x is time (s): they get a cursor and seek on click/drag."""
        self._time_axes = list(axes)
        if self._drawn:
            self._columns = self._axis_columns()
        self._place_cursors()

    def close_plot(self) -> None:
        for unsubscribe in self._unsubscribe:
            unsubscribe()
        self._unsubscribe = []

    # -- cursor ---------------------------------------------------------------
    def resizeEvent(self, event) -> None:  # noqa: N802 (Qt name)
        super().resizeEvent(event)
        self.overlay.setGeometry(self.rect())

    def _on_draw(self, _event) -> None:
        self._drawn = True
        self._picture = None
        self._columns = self._axis_columns()
        self._place_cursors()

    def _axis_columns(self) -> list[tuple[float, float, float, float, int, int]]:
        """Per time axis, as drawn: (x0, x1) its pixel extent, (a, b) time -> pixel x = a t + b
        (widget pixels), (top, bottom) widget pixels.  Taken at each draw, so the cursors match
        the picture on screen until the next draw, and placing them costs no transform."""
        ratio = self.device_pixel_ratio or 1.0
        height = self.figure.bbox.height
        out = []
        for ax in self._time_axes:
            box = ax.bbox
            x_a, x_b = ax.transData.transform([(0.0, 0.0), (1.0, 0.0)])[:, 0]
            out.append(((box.x0 - 0.5) / ratio, (box.x1 + 0.5) / ratio, (x_b - x_a) / ratio, x_a / ratio,
                        int(round((height - box.y1) / ratio)), int(round((height - box.y0) / ratio))))
        return out

    def cursor_columns(self) -> list[tuple[int, int, int]]:
        """(x, top, bottom) widget pixels of the cursor in each time axis (none outside the axis)."""
        if not self._drawn:
            return []
        t = self.cursor_time
        return [(int(round(a * t + b)), top, bottom) for x0, x1, a, b, top, bottom in self._columns
                if x0 <= a * t + b <= x1]

    def _place_cursors(self) -> None:
        self.overlay.set_columns(self.cursor_columns())

    def _on_time(self, event: Event) -> None:
        self.cursor_time = event.value
        self._place_cursors()

    def _figure_picture(self) -> QImage | None:
        """The Agg buffer of the last draw as an opaque QImage (made once per draw), or None
        when the buffer is not the canvas's size (e.g. between a resize and its draw)."""
        renderer = getattr(self, "renderer", None)
        if renderer is None:
            return None
        width, height = self.get_width_height(physical=True)
        if self._picture is None or (self._picture.width(), self._picture.height()) != (width, height):
            rgba = np.asarray(self.buffer_rgba())
            if rgba.shape[:2] != (height, width):
                return None
            # The figure's face is opaque, so its pixels are too: no alpha to premultiply.
            picture = QImage(rgba.data, width, height, 4 * width, QImage.Format.Format_RGBX8888)
            self._picture = picture.convertToFormat(QImage.Format.Format_RGB32)  # a copy, in the screen's format
            self._picture.setDevicePixelRatio(self.device_pixel_ratio or 1.0)
        return self._picture

    def paintEvent(self, event) -> None:  # noqa: N802 (Qt name)
        """Paint the damaged part from the picture of the last draw (matplotlib's paint for
        anything else)."""
        # A pending draw happens first, as in matplotlib's own paint (whose helper this is; its
        # timer draws anyway should a matplotlib version not have it).
        getattr(self, "_draw_idle", lambda: None)()
        picture = self._figure_picture()
        if picture is None:
            super().paintEvent(event)
            return
        rect = event.rect()
        ratio = picture.devicePixelRatio()
        source = QRect(int(rect.left() * ratio), int(rect.top() * ratio),
                       int(np.ceil(rect.width() * ratio)), int(np.ceil(rect.height() * ratio)))
        painter = QPainter(self)
        try:
            painter.drawImage(QPoint(rect.left(), rect.top()), picture, source)
            self._draw_rect_callback(painter)
        finally:
            painter.end()

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
        return int(round(x_px / ratio)), int(round((self.figure.bbox.height - y_px) / ratio))
