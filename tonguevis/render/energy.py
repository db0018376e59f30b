"""Matplotlib figures of energy curves (Fig. 14) and the MDS contrast (Fig. 13), no Qt.

Colours encode the group (e.g. speaker × syllable); each curve is one
production.  Functions draw into a given Axes, or :func:`save_energy_png` makes
a whole figure file (Agg backend, temporary file then rename).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from tonguevis.analysis.energy import EnergyCurve, group_curves


def group_label(key: tuple, by: Sequence[str]) -> str:
    """'spk1 /ka/' style legend text for a group key ('unknown speaker' for an empty label)."""
    parts = []
    for name, value in zip(by, key):
        if value in ("", None):
            parts.append(f"unknown {name}")
            continue
        parts.append(f"/{value}/" if name == "syllable" else f"{name} {value}" if name in ("trial", "train", "index")
                     else str(value))
    return " ".join(parts) or "all"


def plot_energy_curves(ax, curves: Sequence[EnergyCurve], by: Sequence[str] = ("speaker", "syllable"),
                       normalised: bool = True, unit: str = "mJ", colours=None, linewidth: float = 1.2,
                       alpha: float = 0.85) -> dict[tuple, object]:
    """Overlay the curves on ``ax`` coloured by group; returns {group key: colour}.

    normalised : x is normalised production time (0 = release, 1 = next release),
        else seconds since the release.  unit : "J" or "mJ" for the y axis.
    """
    import matplotlib

    scale = {"J": 1.0, "mJ": 1e3, "µJ": 1e6}[unit]
    groups = group_curves(curves, by)
    cmap = matplotlib.colormaps["tab10"]
    colour_of = {}
    for g, (key, members) in enumerate(groups.items()):
        colour = colours[key] if colours and key in colours else cmap(g % 10)
        colour_of[key] = colour
        for k, c in enumerate(members):
            x = c.time_norm if normalised else c.time_s
            ax.plot(x, c.energy * scale, color=colour, lw=linewidth, alpha=alpha,
                    label=group_label(key, by) if k == 0 else None)
    ax.set_xlabel("normalised production time (release → next release)" if normalised
                  else "time since the consonant release (s)")
    ax.set_ylabel(f"elastic energy U = ½ qᵀΛq ({unit})")
    ax.grid(True, alpha=0.3)
    if groups:
        ax.legend(fontsize="small", frameon=False)
    return colour_of


def save_energy_png(curves: Sequence[EnergyCurve], path, by: Sequence[str] = ("speaker", "syllable"),
                    title: str | None = None, dpi: int = 120) -> None:
    """Two panels, absolute and normalised time, written to ``path`` (PNG)."""
    from matplotlib.figure import Figure  # no pyplot: no GUI backend is touched

    fig = Figure(figsize=(11, 4.2), dpi=dpi, layout="constrained")
    left, right = fig.subplots(1, 2, sharey=True)
    plot_energy_curves(left, curves, by, normalised=False)
    plot_energy_curves(right, curves, by, normalised=True)
    right.set_ylabel("")
    if title:
        fig.suptitle(title)
    save_figure(fig, path, dpi)


def save_figure(fig, path, dpi: int = 120) -> None:
    """fig.savefig to a temporary file in the target folder, then rename."""
    from tonguevis._files import atomic_write

    path = Path(path)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format=(path.suffix.lstrip(".") or "png")))


def plot_mds_paths(ax, embedding: np.ndarray, segments: Sequence[tuple[int, int]], labels: Sequence[str],
                   colours=None) -> None:
    """Fig. 13 top: each sequence's frames (rows of ``embedding`` in ``segments`` [start, stop)) joined in order."""
    import matplotlib

    cmap = matplotlib.colormaps["tab10"]
    for k, ((a, b), label) in enumerate(zip(segments, labels)):
        colour = colours[k] if colours else cmap(k % 10)
        xy = embedding[a:b]
        ax.plot(xy[:, 0], xy[:, 1], "-o", color=colour, ms=2.5, lw=0.9, label=label)
    ax.set_xlabel("MDS dimension 1")
    ax.set_ylabel("MDS dimension 2")
    ax.legend(fontsize="small", frameon=False)
    ax.grid(True, alpha=0.3)
