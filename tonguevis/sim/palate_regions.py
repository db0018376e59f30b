"""Where on the palate: its front-to-back and side-to-side regions, as a clinician names them.

A palate (:class:`~tonguevis.palate.PalateSurface`, in the simulation's head frame) is measured along its
midline from its front (the incisors' side of the alveolar ridge) to the end of the hard palate (the hinge of
the velum, :mod:`tonguevis.sim.speaker_palate`; for a palate without one, two thirds of the way back), and
across from its midline.  :func:`palate_frame` gives those references once; :func:`place_of` names where points
are ("front-centre", "back-left"...): thirds of the hard palate front to back (alveolar, palatal, velar: the velum
is "back" too), "centre" within :data:`CENTRE_HALF_WIDTH` of the midline, else "left" (y > 0 side) or "right".
The virtual electropalatograph (:mod:`tonguevis.analysis.epg`) lays its rows out on the same references.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: m: points within this distance of the palate's midline are in its centre.
CENTRE_HALF_WIDTH = 4e-3


@dataclass(frozen=True)
class PalateFrame:
    """The palate's references, m in the head frame: ``front`` and ``hard_end`` (x of its front and of the end of
    its hard palate; x decreases backwards), ``midline`` (y) and ``half_width`` (y extent either side, at its
    widest)."""

    front: float
    hard_end: float
    midline: float
    half_width: float

    @property
    def length(self) -> float:
        """m from the front to the end of the hard palate."""
        return max(self.front - self.hard_end, 1e-9)


def palate_frame(palate) -> PalateFrame:
    """The references of ``palate`` (its grid as placed; its ``speaker_palate`` metadata for the hard palate's
    end and the midline when it has them)."""
    x, y = np.asarray(palate.x), np.asarray(palate.y)
    gx, gy = np.meshgrid(x, y)
    cells = np.column_stack([gx.ravel(), gy.ravel(), np.asarray(palate.z).ravel()])
    ok = np.isfinite(cells[:, 2])
    placed = palate._from_own(cells[ok]) if ok.any() else np.zeros((1, 3))
    front, back = float(placed[:, 0].max()), float(placed[:, 0].min())
    info = palate.metadata.get("speaker_palate") or {}
    hinge = info.get("hinge_x_mm")
    hard_end = 1e-3 * hinge if hinge is not None else back + (front - back) / 3.0
    traced = getattr(palate, "traced", None)
    if traced is not None and np.asarray(traced).any():
        midline = float(np.median(gy[np.asarray(traced, bool)]))
    else:
        midline = float(np.median(placed[:, 1]))
    half = float(np.max(np.abs(placed[:, 1] - midline)))
    return PalateFrame(front, min(hard_end, front - 1e-3), midline, max(half, 1e-3))


def place_of(frame: PalateFrame, points: np.ndarray, weights: np.ndarray | None = None) -> str:
    """Where the (k, 3) head-frame ``points`` are on the palate (their mean, weighted by ``weights``, e.g. the
    areas the contact nodes stand for): "front-centre", "middle-left", "back-right"...; "" without points."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0:
        return ""
    w = np.ones(len(points)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.sum() <= 0:
        w = np.ones(len(points))
    x, y = np.average(points[:, 0], weights=w), np.average(points[:, 1], weights=w)
    along = (frame.front - x) / frame.length  # 0 at the front, 1 at the end of the hard palate
    depth = "front" if along < 1.0 / 3.0 else "middle" if along < 2.0 / 3.0 else "back"
    off = y - frame.midline
    side = "centre" if abs(off) <= CENTRE_HALF_WIDTH else ("left" if off > 0 else "right")
    return f"{depth}-{side}"
