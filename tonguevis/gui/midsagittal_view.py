"""The midsagittal view, shared by the replay app and the live window: the tongue's section in its mid-plane
(x anterior to the right, z up), the palate (traced solid, estimated dashed), the sensors with their trails and
names, the targets, a replay ghost, and a few lines of text (the constriction at the cursor).

Painted with QPainter from segments and points given in metres: no OpenGL, a fraction of a millisecond.  What to
draw at a replay frame comes from :class:`tonguevis.render.midsagittal.MidsagittalSection` (no Qt)."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPointF, Qt
from PySide6.QtGui import QColor, QPainter, QPen
from PySide6.QtWidgets import QWidget

TONGUE_COLOUR = "#d98a8a"
SENSOR_COLOUR = "#2ecc71"
BACKGROUND = "#2b303a"
GHOST_COLOUR = "#9ecbff"
PALATE_COLOUR = "#8fc1e3"
TEXT_COLOUR = "#dddddd"


class MidsagittalView(QWidget):
    """See the module doc.  Set the attributes, then ``update()``:

    segments : (n, 2, 2) the tongue's section; palate : (k, 2, 2) the palate where traced (or all of it when
    unknown), palate_estimated : (k, 2, 2) where estimated (dashed); sensors : (S, 2), sensor_names : S names
    (drawn beside them; empty: none), trails : list of (t, 2) per sensor; targets : (x, z, radius m, rgb);
    ghost : (g, 2) a replay target's path; lines : text at the top left (below the title)."""

    def __init__(self, parent=None, title: str = "midsagittal (anterior →)"):
        super().__init__(parent)
        self.setMinimumSize(220, 160)
        self.title = title
        self.segments = np.zeros((0, 2, 2))
        self.palate = np.zeros((0, 2, 2))
        self.palate_estimated = np.zeros((0, 2, 2))
        self.sensors = np.zeros((0, 2))
        self.sensor_names: list[str] = []
        self.trails: list[np.ndarray] = []
        self.targets: list[tuple[float, float, float, tuple]] = []  # x, z, radius (m), rgb
        self.ghost = np.zeros((0, 2))
        self.lines: list[str] = []
        self.bounds: tuple[float, float, float, float] | None = None  # xmin, xmax, zmin, zmax (m)

    def set_bounds(self, points_xz: np.ndarray, margin: float = 0.25) -> None:
        points_xz = np.asarray(points_xz, dtype=np.float64).reshape(-1, 2)
        points_xz = points_xz[np.all(np.isfinite(points_xz), axis=1)]
        if not len(points_xz):
            return
        lo, hi = points_xz.min(axis=0), points_xz.max(axis=0)
        pad = margin * float(max(hi - lo))
        self.bounds = (lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad)

    def _mapper(self):
        x0, x1, z0, z1 = self.bounds
        w, h = max(self.width(), 1), max(self.height(), 1)
        scale = min(w / max(x1 - x0, 1e-9), h / max(z1 - z0, 1e-9))
        cx, cz = (x0 + x1) / 2, (z0 + z1) / 2
        return scale, (lambda x, z: QPointF(w / 2 + scale * (x - cx), h / 2 - scale * (z - cz)))

    def paintEvent(self, _event) -> None:  # noqa: N802 (Qt name)
        painter = QPainter(self)
        painter.fillRect(self.rect(), QColor(BACKGROUND))
        painter.setPen(QColor("#cccccc"))
        painter.drawText(6, 16, self.title)
        painter.setPen(QColor(TEXT_COLOUR))
        for k, line in enumerate(self.lines):
            painter.drawText(6, 34 + 16 * k, line)
        if self.bounds is None:
            painter.end()
            return
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        scale, at = self._mapper()
        for segments, colour, width, style in (
                (self.palate, PALATE_COLOUR, 2, Qt.PenStyle.SolidLine),
                (self.palate_estimated, PALATE_COLOUR, 1.5, Qt.PenStyle.DashLine),
                (self.segments, TONGUE_COLOUR, 2.5, Qt.PenStyle.SolidLine)):
            painter.setPen(QPen(QColor(colour), width, style))
            for (xa, za), (xb, zb) in segments:
                painter.drawLine(at(xa, za), at(xb, zb))
        if len(self.ghost):
            painter.setPen(QPen(QColor(GHOST_COLOUR), 1.5, Qt.PenStyle.DashLine))
            ok = self.ghost[np.all(np.isfinite(self.ghost), axis=1)]
            for a, b in zip(ok[:-1], ok[1:]):
                painter.drawLine(at(*a), at(*b))
        trail = QColor(SENSOR_COLOUR)
        trail.setAlphaF(0.5)
        painter.setPen(QPen(trail, 1.5))
        for path in self.trails:
            ok = path[np.all(np.isfinite(path), axis=1)]
            for a, b in zip(ok[:-1], ok[1:]):
                painter.drawLine(at(*a), at(*b))
        for x, z, r, rgb in self.targets:
            if not (np.isfinite(x) and np.isfinite(z)):
                continue
            painter.setPen(QPen(QColor.fromRgbF(*rgb), 2))
            painter.drawEllipse(at(x, z), scale * r, scale * r)
        painter.setPen(Qt.PenStyle.NoPen)
        painter.setBrush(QColor(SENSOR_COLOUR))
        for x, z in self.sensors:
            if np.isfinite(x) and np.isfinite(z):
                painter.drawEllipse(at(x, z), 4, 4)
        painter.setPen(QColor(SENSOR_COLOUR))
        for name, (x, z) in zip(self.sensor_names, self.sensors):
            if np.isfinite(x) and np.isfinite(z):
                p = at(x, z)
                painter.drawText(QPointF(p.x() + 6, p.y() - 6), name)
        painter.end()
