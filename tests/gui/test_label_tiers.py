"""Label tiers under the waveform: one row per tier, texts, the cursor across them, click to seek."""

from __future__ import annotations

import pytest

pytest.importorskip("PySide6")

from tests.gui.fakes import fake_recording  # noqa: E402
from tonguevis.io.recording import Label  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(60)]

LABELS = [Label(0.2, 0.6, "the", "words"), Label(0.6, 1.4, "birch", "words"),
          Label(0.2, 0.3, "DH", "phones"), Label(0.3, 0.6, "AH0", "phones"), Label(0.6, 0.65, "B", "phones"),
          Label(0.9, 0.9, "release", "events")]


@pytest.fixture
def plot(qtbot):
    from tonguevis.appstate import AppState
    from tonguevis.gui.audio_panel import AudioPlot

    state = AppState()
    state.set_range(0.0, 2.0, 0.01)
    widget = AudioPlot(state)
    qtbot.addWidget(widget)
    widget.resize(1000, 300)
    widget.show()
    qtbot.waitExposed(widget)
    yield widget
    widget.close_plot()


def shown(qtbot, plot, labels):
    rec = fake_recording()
    plot._drawn = False
    plot.show_audio(rec.audio, (0.0, 2.0), labels=labels)
    plot.draw()
    qtbot.waitUntil(lambda: plot._drawn, timeout=5000)


def row_y(plot, k):
    """The data y of the middle of tier row k (0 = top)."""
    return plot.n_tiers - k - 0.5


def test_one_row_per_tier_with_names_and_texts(qtbot, plot):
    shown(qtbot, plot, LABELS)
    ax = plot.tiers_ax
    assert ax is not None and plot.n_tiers == 3
    assert [t.get_text() for t in ax.get_yticklabels()] == ["words", "phones", "events"]
    texts = {t.get_text(): t for t in ax.texts}
    assert {"the", "birch", "DH", "AH0", "B"} <= set(texts)
    assert any(t.get_text().strip() == "release" for t in ax.texts)
    # each text sits in its tier's row, between its boundaries
    assert texts["birch"].get_position() == pytest.approx((1.0, row_y(plot, 0)))
    assert texts["AH0"].get_position() == pytest.approx((0.45, row_y(plot, 1)))
    # boundaries: vertical segments at every interval's start and end
    xs = sorted({round(float(x), 6) for coll in ax.collections for seg in coll.get_segments() for x in seg[:, 0]})
    for t in (0.2, 0.3, 0.6, 0.65, 0.9, 1.4):
        assert t in xs
    # the tiers share the waveform's time axis
    assert ax.get_xlim() == pytest.approx(plot.wave_ax.get_xlim())


def test_texts_too_wide_for_their_interval_are_hidden(qtbot, plot):
    crowded = [Label(0.0, 0.004, "a long phone label", "phones"), Label(0.004, 1.0, "wide", "phones")]
    shown(qtbot, plot, crowded)
    texts = {t.get_text(): t for t in plot.tiers_ax.texts}
    assert texts["wide"].get_visible()
    assert not texts["a long phone label"].get_visible()


def test_cursor_runs_across_the_tiers_and_a_click_there_seeks(qtbot, plot):
    from PySide6.QtCore import QPoint, Qt

    shown(qtbot, plot, LABELS)
    ax = plot.tiers_ax
    plot.state.set_time(1.0)
    columns = plot.overlay.columns
    assert len(columns) == 3  # waveform, spectrogram and tiers
    x_cursor, _ = plot.data_to_widget(ax, 1.0, row_y(plot, 1))
    _, top = plot.data_to_widget(ax, 1.0, plot.n_tiers)
    _, bottom = plot.data_to_widget(ax, 1.0, 0.0)
    assert any(abs(x - x_cursor) <= 1 and abs(t - top) <= 2 and abs(b - bottom) <= 2 for x, t, b in columns)
    x, y = plot.data_to_widget(ax, 0.45, row_y(plot, 1))
    qtbot.mouseClick(plot, Qt.MouseButton.LeftButton, pos=QPoint(x, y))
    assert plot.state.time == pytest.approx(0.45, abs=0.01)


def test_without_labels_there_is_no_tier_row(qtbot, plot):
    shown(qtbot, plot, LABELS)
    with_tiers = plot.minimumHeight()
    shown(qtbot, plot, [])
    assert plot.minimumHeight() < with_tiers  # the rows asked for room of their own
    assert plot.tiers_ax is None and plot.n_tiers == 0
    assert len(plot.figure.axes) == 2
    assert len(plot.overlay.columns) == 2


def test_window_shows_the_recordings_tiers(qtbot, window):
    from dataclasses import replace

    from tonguevis.workflows.session import make_session

    rec = replace(fake_recording(names=("TT", "TD", "TL", "TR")), labels=LABELS)
    window.show_session(make_session(rec))
    assert window.audio.n_tiers == 3
    assert "birch" in {t.get_text() for t in window.audio.tiers_ax.texts}
    window.controller.stop("primary")
