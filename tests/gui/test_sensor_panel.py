"""The sensor panel fits its axes to the tongue: references and other channels only on request."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")

from tonguevis.io.recording import Recording  # noqa: E402

pytestmark = pytest.mark.gui

TONGUE = ("TT", "TD")
OTHERS = ("JAW", "S0", "S7", "S2", "REF1")


def export_like_recording() -> Recording:
    """What a real NDI Wave export looks like once mapped: two tongue sensors moving a few mm
    after a still second, the jaw, an unmapped reference 120 mm away (S0), a constant
    placeholder (S7), a port with no valid sample (S2) and a mapped head reference."""
    rate = 100.0
    times = np.arange(300) / rate
    moving = np.where(times > 1.2, np.sin(2 * np.pi * 1.5 * (times - 1.2)), 0.0)[:, None]
    settle = np.where(times < 0.05, 1.0, 0.0)[:, None]  # the first samples before the tongue came to rest
    tongue_tip = np.array([-0.019, 0.0, -0.010])
    sensors = {
        "TT": tongue_tip + moving * [0.004, 0.001, 0.006] + settle * 0.002,
        "TD": np.array([-0.039, 0.0, -0.005]) + moving * [0.002, 0.0005, 0.003],
        "JAW": np.array([-0.003, 0.0, -0.024]) + moving * [0.0, 0.0, 0.002],
        "S0": np.tile(tongue_tip + [0.120, 0.080, 0.060], (len(times), 1)),
        "S7": np.tile([-0.200, -0.150, 0.100], (len(times), 1)),
        "S2": np.full((len(times), 3), np.nan),
        "REF1": np.tile([-0.085, 0.062, -0.018], (len(times), 1)),
    }
    return Recording(rate, times, sensors, metadata={"format": "test", "file": "export.tsv"})


@pytest.fixture
def panel(qtbot):
    from tonguevis.appstate import AppState
    from tonguevis.gui.sensor_panel import SensorPanel
    from tonguevis.workflows.session import Session

    widget = SensorPanel(AppState())
    qtbot.addWidget(widget)
    widget.resize(700, 600)
    widget.show()
    qtbot.waitExposed(widget)
    widget.set_session(Session(export_like_recording()))
    yield widget
    widget.plot.close_plot()


def _range(names, k):
    rec = export_like_recording()
    values = np.concatenate([rec.sensors[n][:, k] for n in names]) * 1e3
    values = values[np.isfinite(values)]
    return values.min(), values.max()


def test_position_axes_fit_the_tongue_by_default(panel):
    assert not panel.others.isChecked()
    assert set(panel.plot.lines) == set(TONGUE)
    assert "(5)" in panel.others.text()  # says how many channels it hides
    for k, ax in enumerate(panel.plot.axes):
        low, high = ax.get_ylim()
        t_low, t_high = _range(TONGUE, k)
        assert low <= t_low and t_high <= high
        assert high - low < 1.5 * (t_high - t_low)  # the tongue's traces fill the axis
        for name in ("S0", "S7", "REF1"):  # the far reference and the placeholders are off the axis
            value = export_like_recording().sensors[name][0, k] * 1e3
            assert not low <= value <= high, (name, k, value, (low, high))


def test_the_toggle_shows_every_channel_and_hides_them_again(panel, qtbot):
    from PySide6.QtCore import Qt

    qtbot.mouseClick(panel.others, Qt.MouseButton.LeftButton)
    assert panel.others.isChecked()
    assert set(panel.plot.lines) == set(TONGUE + OTHERS)
    colour = panel.plot.lines["S0"][0].get_color()
    for k, ax in enumerate(panel.plot.axes):
        low, high = ax.get_ylim()
        everything = _range(TONGUE + OTHERS, k)
        assert low <= everything[0] and everything[1] <= high
    panel.set_kind("velocity")  # the choice holds for every kind
    assert set(panel.plot.lines) == set(TONGUE + OTHERS)
    panel.set_kind("position")
    panel.set_show_others(False)
    assert set(panel.plot.lines) == set(TONGUE)
    low, high = panel.plot.axes[0].get_ylim()
    assert high - low < 1.5 * np.subtract(*_range(TONGUE, 0)[::-1])
    panel.set_show_others(True)
    assert panel.plot.lines["S0"][0].get_color() == colour  # a channel keeps its colour


def test_a_motion_redraws_only_the_displacements(panel):
    """The app model calls set_session again when the session's motion comes: positions, velocities
    and accelerations stay as drawn; displacements (from the simulation's rest) are redrawn."""
    session = panel.session
    drawn = panel.plot.lines["TT"][0]
    panel.set_session(session)
    assert panel.plot.lines["TT"][0] is drawn
    panel.set_kind("displacement")
    drawn = panel.plot.lines["TT"][0]
    panel.set_session(session)
    assert panel.plot.lines["TT"][0] is not drawn
    panel.set_session(None)
    assert panel.session is None


def test_a_long_trace_is_drawn_as_its_envelope():
    """Past MAX_TRACE_POINTS samples a trace is its lowest and highest value per bin: the same extremes,
    gaps kept, a bounded number of points; a short one is drawn sample by sample."""
    from tonguevis.gui.sensor_panel import MAX_TRACE_POINTS, TRACE_BINS, envelope_trace

    rng = np.random.default_rng(1)
    n = 3 * MAX_TRACE_POINTS + 17
    times = np.arange(n) / 100.0
    values = np.cumsum(rng.normal(size=n))
    values[1000:1200] = np.nan  # a dropout wider than a bin
    t, v = envelope_trace(times, values)
    assert len(t) == len(v) == 2 * TRACE_BINS
    assert np.nanmin(v) == np.nanmin(values) and np.nanmax(v) == np.nanmax(values)
    assert np.all(np.diff(t) >= 0) and t[0] == times[0] and t[-1] == times[-1]
    gap = (t > 10.2) & (t < 11.8)
    assert gap.any() and np.isnan(v[gap]).all()
    edges = np.linspace(0, n, TRACE_BINS + 1).astype(int)
    k = 4000  # any bin: its two points are that bin's extremes
    assert v[2 * k] == values[edges[k]:edges[k + 1]].min() and v[2 * k + 1] == values[edges[k]:edges[k + 1]].max()
    short = np.arange(2 * TRACE_BINS, dtype=float)
    assert envelope_trace(short, short)[1] is short


def test_the_panel_draws_a_long_recording_as_envelopes(panel):
    from tonguevis.gui.sensor_panel import MAX_TRACE_POINTS, TRACE_BINS
    from tonguevis.workflows.session import Session

    n = MAX_TRACE_POINTS + 1
    times = np.arange(n) / 100.0
    wave = 0.005 * np.sin(times)[:, None] * [1.0, 0.5, 2.0]
    long_rec = Recording(100.0, times, {"TT": wave, "TD": wave + 0.01}, metadata={"file": "long.tsv"})
    panel.set_session(Session(long_rec))
    for name in ("TT", "TD"):
        for k, line in enumerate(panel.plot.lines[name]):
            assert len(line.get_xdata()) == 2 * TRACE_BINS
            assert np.max(line.get_ydata()) == pytest.approx(1e3 * long_rec.sensors[name][:, k].max())
    assert len(panel.plot.lines["TT"][0].get_xdata()) < n


def test_displacements_from_rest_despite_a_channel_without_samples():
    """A dead port (S2, all NaN) must not push every sensor's rest to its first sample."""
    from tonguevis.workflows.session import Session

    rec = export_like_recording()
    displacement = Session(rec).signals("displacement")
    still = (rec.times > 0.2) & (rec.times < 1.1)
    assert np.abs(displacement["TT"][still]).max() < 1e-6  # rest = the still second, not the first sample
    assert np.all(np.isnan(displacement["S2"]))
    assert list(displacement)[-1] == "REF1"  # references last


def test_the_plot_paints_what_matplotlib_drew_and_its_cursor(panel, qtbot, monkeypatch):
    """The plot's paint (from a copy of the figure made once per draw) shows what matplotlib's
    own paint shows, pixel for pixel (at the screen's depth), the cursor overlay the time, and
    a new draw replaces the copy."""
    from PySide6.QtCore import QPoint, QRect
    from PySide6.QtGui import QImage, QRegion

    from tonguevis.gui.timeplot import TimePlot

    plot = panel.plot
    qtbot.waitUntil(lambda: plot._drawn, timeout=5000)

    def painted(matplotlib_paint: bool = False) -> np.ndarray:
        with monkeypatch.context() as patch:
            if matplotlib_paint:
                patch.setattr(TimePlot, "_figure_picture", lambda self: None)
            image = plot.grab().toImage().convertToFormat(QImage.Format.Format_RGB888)
        rows = np.frombuffer(image.constBits(), dtype=np.uint8).reshape(image.height(), image.bytesPerLine())
        return rows[:, : 3 * image.width()].reshape(image.height(), image.width(), 3).astype(int)

    plot.overlay.hide()
    before = painted()
    np.testing.assert_array_equal(before, painted(matplotlib_paint=True))
    assert before.std() > 10  # a figure with lines and labels, not a blank
    plot.axes[0].set_facecolor("#c0e0ff")
    plot.draw()
    after = painted()
    assert np.abs(after - before).sum() > 0  # the new draw, not the old copy
    np.testing.assert_array_equal(after, painted(matplotlib_paint=True))

    def rendered(region=None) -> np.ndarray:
        image = QImage(plot.size(), QImage.Format.Format_RGB32)
        image.fill(0)
        plot.render(image, QPoint(0, 0), QRegion(region if region is not None else plot.rect()))
        return np.frombuffer(image.constBits(), dtype=np.uint32).reshape(image.height(), -1)[:, : image.width()].copy()

    # A cursor's strip repaints alone, with the figure's own pixels there (QWidget.render puts
    # the region's corner at the target's origin).
    strip = QRect(plot.width() // 2 - 2, 0, 5, plot.height())
    whole, part = rendered(), rendered(strip)
    np.testing.assert_array_equal(part[:, : strip.width()], whole[:, strip.left(): strip.right() + 1])
    assert (part[:, strip.width():] & 0xFFFFFF == 0).all()  # nothing painted outside it
    plot.overlay.show()
    panel.state.set_time(1.5)
    columns = plot.cursor_columns()
    assert columns
    with_cursor = painted()
    x, top, bottom = columns[0]
    middle = (top + bottom) // 2
    assert np.abs(with_cursor[middle, x] - after[middle, x]).sum() > 60  # the red line
    np.testing.assert_array_equal(with_cursor[:, : x - 3], after[:, : x - 3])  # nothing else changed
