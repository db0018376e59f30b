"""Matplotlib figures of repetitions: time-normalised mean ± SD trajectories per sensor, with the STI (no Qt).

:func:`draw_averages` draws into a given Figure (the app's Measures tab embeds one),
:func:`save_averages_png` writes a whole figure file (Agg, temporary file then rename).
"""

from __future__ import annotations

import numpy as np

from tonguevis.analysis.repetitions import PERCENT

#: Colours of the groups (or of the one set), as the energy figures'.
_CMAP = "tab10"


def _groups(repetitions):
    """[(name, Repetitions)] from one Repetitions or a {group name: Repetitions} mapping."""
    if hasattr(repetitions, "records_mm"):
        return [("", repetitions)]
    return list(repetitions.items())


def draw_averages(figure, repetitions, sensors=None, columns: int = 3, zscores: bool = False) -> list:
    """One panel per sensor: the mean vertical position (mm, or z-scored) over normalised time with a ± 1 SD
    band, each group in its colour, its STI and n in the legend; returns the axes.

    repetitions : a :class:`~tonguevis.analysis.repetitions.Repetitions`, or {group name: Repetitions}.
    sensors : the sensors to draw (default: every sensor of the first group, in its order).
    """
    import matplotlib

    groups = [(group, reps) for group, reps in _groups(repetitions) if reps.n > 0]
    figure.clear()
    names = list(sensors) if sensors is not None else (groups[0][1].sensors if groups else [])
    if not groups:
        names = []
    if not names:
        ax = figure.add_subplot(1, 1, 1)
        ax.set_axis_off()
        ax.text(0.5, 0.5, "no productions to average", ha="center", va="center")
        return [ax]
    columns = max(1, min(columns, len(names)))
    rows = -(-len(names) // columns)
    axes = figure.subplots(rows, columns, squeeze=False).ravel()
    cmap = matplotlib.colormaps[_CMAP]
    for ax, name in zip(axes, names):
        for g, (group, reps) in enumerate(groups):
            values = (reps.zscores if zscores else reps.records_mm).get(name)
            if values is None or len(values) == 0:
                continue
            mean = values.mean(axis=0)
            sd = values.std(axis=0, ddof=1) if len(values) > 1 else np.zeros_like(mean)
            sti = reps.sti.get(name, float("nan"))
            colour = cmap(g % 10)
            figures = f"STI {sti:.1f}, n = {reps.n}" if np.isfinite(sti) else f"n = {reps.n}"
            ax.fill_between(PERCENT, mean - sd, mean + sd, color=colour, alpha=0.22, lw=0)
            ax.plot(PERCENT, mean, color=colour, lw=1.6, label=f"{group}: {figures}" if group else figures)
        if len(groups) == 1 and ax.get_lines():  # one set: its figures in the title, no legend over the curve
            ax.set_title(f"{name}  {ax.get_lines()[0].get_label()}", fontsize=8, loc="left")
        else:
            ax.set_title(name, fontsize=8, loc="left")
            ax.legend(fontsize=7, frameon=False, loc="best")
        ax.set_xlim(0, 100)
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=7)
    for ax in axes[len(names):]:
        ax.set_axis_off()
    unit = "z-score" if zscores else "mm"
    for ax in axes[:len(names):columns]:
        ax.set_ylabel(f"height z ({unit})", fontsize=8)
    axes[(rows - 1) * columns].set_xlabel("normalised time (%)", fontsize=8)
    return list(axes[:len(names)])


def save_averages_png(repetitions, path, title: str | None = None, sensors=None, dpi: int = 120,
                      zscores: bool = False) -> None:
    """The figure of :func:`draw_averages` written to ``path`` (PNG, or the suffix's format)."""
    from matplotlib.figure import Figure  # no pyplot: no GUI backend is touched

    from tonguevis.render.energy import save_figure

    groups = _groups(repetitions)
    count = len(sensors) if sensors is not None else (len(groups[0][1].sensors) if groups else 1)
    columns = min(3, max(count, 1))
    rows = -(-max(count, 1) // columns)
    fig = Figure(figsize=(3.6 * columns + 0.6, 2.6 * rows + (0.5 if title else 0.2)), dpi=dpi, layout="constrained")
    draw_averages(fig, repetitions, sensors, columns, zscores)
    if title:
        fig.suptitle(title, fontsize=10)
    save_figure(fig, path, dpi)
