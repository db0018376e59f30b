"""Productions and gesture landmarks drawn on matplotlib time axes (no Qt).

Shared by the app's sensor and sound panels and by figures: each production shaded
(alternating colours) with its start dashed, and its gesture landmarks as markers on
the articulator's trace (or along the top of an axes without one).  A few artists per
axes however many productions (one per production made a 30-minute recording take
minutes to draw).
"""

from __future__ import annotations

import numpy as np

#: landmark key -> (marker, colour, legend text); keys of tonguevis.preprocess.gestures.LANDMARKS
LANDMARK_STYLE = {
    "gons": ("|", "#1e8449", "gesture onset / offset"),
    "goffs": ("|", "#1e8449", None),
    "pvel": ("x", "#d35400", "peak velocity"),
    "pvel2": ("x", "#d35400", None),
    "nons": ("|", "#7d3c98", "nucleus onset / offset"),
    "noffs": ("|", "#7d3c98", None),
    "maxc": ("o", "#c0392b", "maximum constriction"),
    "vowel": ("s", "#2471a3", "vowel target"),
}
SHADES = ("#95a5a6", "#3498db")


def shade_productions(ax, spans, alpha: float = 0.12) -> list:
    """Shade each (start_s, end_s) of ``spans`` across ``ax`` and dash its start; returns the artists."""
    from matplotlib.collections import LineCollection, PolyCollection

    spans = np.asarray(spans, dtype=np.float64).reshape(-1, 2)
    if not len(spans):
        return []
    band = ax.get_xaxis_transform()  # x in seconds, y from the bottom (0) to the top (1) of the axes
    boxes = [[(a, 0.0), (a, 1.0), (b, 1.0), (b, 0.0)] for a, b in spans]
    colours = [SHADES[j % 2] for j in range(len(spans))]
    shade = PolyCollection(boxes, facecolors=colours, alpha=alpha, linewidths=0, transform=band)
    starts = LineCollection([[(a, 0.0), (a, 1.0)] for a in spans[:, 0]], colors="#7f8c8d", linewidths=0.6,
                            linestyles="--", transform=band)
    ax.add_collection(shade, autolim=False)
    ax.add_collection(starts, autolim=False)
    return [shade, starts]


def landmark_points(landmarks, times: np.ndarray | None = None, trace: np.ndarray | None = None) -> dict:
    """{key: (t (K,), y (K,))} of every landmark of ``landmarks`` (GestureLandmarks), at the
    ``trace`` (N,) sampled at ``times`` (N,) when given (NaN y otherwise)."""
    out = {}
    for key in LANDMARK_STYLE:
        t = np.array([m.times[key] for m in landmarks], dtype=np.float64)
        t = t[np.isfinite(t)]
        if times is not None and trace is not None and len(times):
            ok = np.isfinite(trace)
            y = np.interp(t, times[ok], trace[ok]) if ok.any() else np.full_like(t, np.nan)
        else:
            y = np.full_like(t, np.nan)
        out[key] = (t, y)
    return out


def mark_landmarks(ax, landmarks, times: np.ndarray | None = None, trace: np.ndarray | None = None,
                   legend: bool = False, size: float = 6.0, above: bool = False) -> list:
    """Markers of ``landmarks`` on ``trace`` (its y at each landmark time), or along the top
    of ``ax`` without one; a legend of the kinds when asked (inside the axes' lower right, or
    above them with ``above``).  Returns the artists."""
    artists = []
    on_trace = trace is not None
    for key, (t, y) in landmark_points(landmarks, times, trace).items():
        if not len(t):
            continue
        marker, colour, label = LANDMARK_STYLE[key]
        # ticks and crosses are drawn as lines: larger and bolder than the filled markers to show as much
        style = {"markersize": size if marker in "os" else 1.6 * size, "markeredgewidth": 1.0 if marker in "os" else 1.8,
                 "markerfacecolor": colour if marker in "os" else "none", "linestyle": "none", "marker": marker,
                 "color": colour, "label": label or "_nolegend_", "zorder": 5}
        if on_trace:
            (line,) = ax.plot(t, y, **style)
        else:
            (line,) = ax.plot(t, np.full_like(t, 0.93), transform=ax.get_xaxis_transform(), **style)
        artists.append(line)
    if legend and artists:
        place = {"loc": "lower right", "bbox_to_anchor": (1.0, 1.0)} if above else {"loc": "lower right"}
        handles = [a for a in artists if not a.get_label().startswith("_")]
        artists.append(ax.legend(handles=handles, fontsize=6, frameon=not above, framealpha=0.8,
                                 ncol=legend_columns(ax, [h.get_label() for h in handles], 6.0), handlelength=1.0,
                                 borderaxespad=0.2, columnspacing=0.8, **place))
    return artists


def legend_columns(ax, labels: list[str], fontsize: float, most: int = 5) -> int:
    """How many columns of ``labels`` (at ``fontsize`` points) fit across ``ax`` as it is drawn now: five
    across a wide plot, fewer in a narrow window, where five ran past the axes' left edge."""
    if not labels:
        return 1
    width_px = ax.get_window_extent().width
    char_px = 0.6 * fontsize * ax.figure.dpi / 72.0  # a generous average for the sans-serif font
    column_px = max(len(label) for label in labels) * char_px + 3.0 * fontsize * ax.figure.dpi / 72.0
    return int(max(1, min(most, len(labels), width_px // column_px)))


def interval_at(intervals: list[tuple[float, float]], t: float) -> tuple[float, float] | None:
    """The ``(start, end)`` interval containing time ``t`` (the first one), or None."""
    for start, end in intervals:
        if start <= t <= end:
            return (float(start), float(end))
    return None
