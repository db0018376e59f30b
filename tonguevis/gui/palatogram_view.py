"""A palatogram as EPG software draws it: the Reading palate's 62 electrodes in 8 rows (row 1, the alveolar
ridge, at the top; column 1 on the speaker's left, drawn on the left), the contacted ones filled, and the
indices below (:mod:`tonguevis.analysis.epg`).  For the replay app's Midsagittal tab and the live window."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QRectF, Qt
from PySide6.QtGui import QColor, QPainter, QPen
from PySide6.QtWidgets import QWidget

from tonguevis.analysis.epg import COLUMNS, READING, ROWS, epg_indices

LIT = "#e0574f"
UNLIT = "#3d4450"
BACKGROUND = "#2b303a"
TEXT = "#dddddd"


class PalatogramView(QWidget):
    """See the module doc.  :meth:`show_contacts` with (8, 8) contacts (None: no palatogram, with a reason)."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setMinimumSize(150, 190)
        self.setToolTip("The Reading EPG palate's 62 electrodes on this palate, lit where the simulated tongue "
                        "touches it (within 1 mm). CoG: centre of gravity, 7.5 at the front row to 0.5 at the back; "
                        "anteriority and posteriority: Fontdevila et al.'s indices (0 to 1)")
        self.contacts: np.ndarray | None = None
        self.note = "no palatogram"
        self.indices: dict[str, float] = {}

    def show_contacts(self, contacts: np.ndarray | None, note: str = "") -> None:
        """Draw ``contacts`` (8, 8) bool, ``note`` above it (the time); None: only the note (why there is none)."""
        self.contacts = None if contacts is None else np.asarray(contacts, dtype=bool) & READING
        self.note = note
        if self.contacts is not None:
            idx = epg_indices(self.contacts)
            self.indices = {name: float(values[0]) for name, values in idx.items()}
        else:
            self.indices = {}
        self.update()

    def lines(self) -> list[str]:
        """The indices as printed below the grid."""
        if not self.indices:
            return []
        cog = self.indices["cog"]
        return [f"contact {self.indices['percent_contact']:.0f} %",
                "CoG " + ("–" if not np.isfinite(cog) else f"{cog:.2f}"),
                f"anterior {self.indices['anteriority']:.2f}", f"posterior {self.indices['posteriority']:.2f}"]

    def paintEvent(self, _event) -> None:  # noqa: N802 (Qt name)
        painter = QPainter(self)
        painter.fillRect(self.rect(), QColor(BACKGROUND))
        painter.setPen(QColor(TEXT))
        painter.drawText(6, 16, "palatogram (front ↑)")
        painter.drawText(6, 32, self.note)
        lines = self.lines()
        text_h = 16 * len(lines) + 6
        top, left = 40.0, 6.0
        size = min((self.width() - 2 * left) / COLUMNS, (self.height() - top - text_h - 4) / ROWS)
        if size > 2 and self.contacts is not None:
            painter.setRenderHint(QPainter.RenderHint.Antialiasing)
            x0 = (self.width() - size * COLUMNS) / 2
            for r in range(ROWS):
                for c in range(COLUMNS):
                    if not READING[r, c]:
                        continue
                    cell = QRectF(x0 + c * size + 0.15 * size, top + r * size + 0.15 * size, 0.7 * size, 0.7 * size)
                    painter.setPen(QPen(QColor("#808890"), 1))
                    painter.setBrush(QColor(LIT if self.contacts[r, c] else UNLIT))
                    painter.drawEllipse(cell)
            painter.setBrush(Qt.BrushStyle.NoBrush)
            painter.setPen(QColor(TEXT))
            y = top + ROWS * size + 16
            for line in lines:
                painter.drawText(6, int(y), line)
                y += 16
        painter.end()
