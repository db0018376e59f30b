"""The landmarks' legend on the sensor plots (issue 37, item 2)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest


@pytest.mark.parametrize("width_in", [3.4, 5.0, 9.0])
def test_the_landmark_legend_stays_inside_a_narrow_plot(width_in):
    """Five columns ran past the axes' left edge in the sensor panel at 1280 pixels ("jesture onset")."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from tonguevis.render.production_marks import LANDMARK_STYLE, mark_landmarks

    marks = [SimpleNamespace(times={key: 1.0 + 0.1 * k for k, key in enumerate(LANDMARK_STYLE)})]
    figure = Figure(figsize=(width_in, 2.5), dpi=100)
    canvas = FigureCanvasAgg(figure)
    ax = figure.subplots()
    ax.set_xlim(0.0, 3.0)
    legend = mark_landmarks(ax, marks, legend=True)[-1]
    canvas.draw()
    box, axes = legend.get_window_extent(canvas.get_renderer()), ax.get_window_extent()
    assert axes.x0 - 1 <= box.x0 and box.x1 <= axes.x1 + 1, (box, axes)
    if width_in >= 9.0:
        assert legend._ncols == 5  # one row where there is room
