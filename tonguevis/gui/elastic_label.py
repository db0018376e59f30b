"""A label whose changing text never resizes the window."""

from __future__ import annotations

from PySide6.QtCore import QSize
from PySide6.QtWidgets import QLabel


class ElasticLabel(QLabel):
    """A one-line QLabel that asks for its text's width but needs only ``minimum_width`` pixels.

    A plain QLabel's minimum width is its text's: a status line that grows by a word at some
    frame raises the window's minimum width, and the window (and with it the 3D views, which
    then render at their new size) resizes in the middle of playback.  This one is cut at the
    right edge instead when the window is narrower than its text.
    """

    def __init__(self, text: str = "", minimum_width: int = 120, parent=None):
        super().__init__(text, parent)
        self._minimum_width = int(minimum_width)

    def minimumSizeHint(self) -> QSize:  # noqa: N802 (Qt name)
        hint = super().minimumSizeHint()
        return QSize(min(hint.width(), self._minimum_width), hint.height())
