"""The Energy tab: grouping, filters, hover text, clicking a point moves the app's time."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")

from tonguevis.analysis.energy import EnergyCurve  # noqa: E402
from tonguevis.appstate import AppState  # noqa: E402
from tonguevis.sim.settings import RunSettings  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


def _curve(recording, speaker, syllable, train, peak, start):
    t = np.arange(0, 0.3, 0.01)
    e = peak * np.sin(np.pi * t / 0.3) ** 2
    return EnergyCurve(recording=recording, speaker=speaker, syllable=syllable, trial=1, train=train, index=2,
                       times=start + t, time_s=t, time_norm=t / 0.3, energy=e, frames=np.arange(len(t)) + 100 * train,
                       start=start, end=start + 0.3)


@pytest.fixture
def curves():
    out = []
    for rec, spk, syl, peak in (("spk1_ka", "spk1", "ka", 2e-3), ("spk2_ka", "spk2", "ka", 1e-3),
                                ("spk1_la", "spk1", "la", 3e-3)):
        out += [_curve(rec, spk, syl, train, peak * (1 + 0.05 * train), 5.0 + train) for train in (1, 2, 3)]
    return out


@pytest.fixture
def tab(qtbot, curves):
    from tonguevis.gui.energy_tab import EnergyTab

    state = AppState(0.0, 20.0, 0.01)
    widget = EnergyTab(state, current_recording=lambda: "spk1_ka")
    qtbot.addWidget(widget)
    widget.resize(1000, 600)
    widget.set_curves(curves)
    widget.show()
    qtbot.waitExposed(widget)
    return widget


def test_curves_grouped_with_legend(tab, tmp_path):
    assert len(tab.lines) == 9
    labels = [t.get_text() for t in tab.axes.get_legend().get_texts()]
    assert labels == ["spk1 /ka/", "spk2 /ka/", "spk1 /la/"]
    colours = {tuple(line.get_color()) for line in tab.lines}
    assert len(colours) == 3
    tab.grab().save(str(tmp_path / "energy_tab.png"))


def test_filters_hide_curves(tab):
    tab.set_ticked(tab.speakers, {"spk1"})
    assert len(tab.lines) == 6 and {c.speaker for c in tab.shown} == {"spk1"}
    tab.set_ticked(tab.syllables, {"la"})
    assert len(tab.lines) == 3 and {c.recording for c in tab.shown} == {"spk1_la"}
    tab.set_ticked(tab.speakers, set())
    assert tab.lines == [] and tab.shown == []


def _click_at(tab, qtbot, curve, k, button=True):
    from PySide6 import QtCore

    tab.canvas.draw()
    x, y = tab.axes.transData.transform((curve.time_norm[k], curve.energy[k] * 1e3))
    ratio = tab.canvas.device_pixel_ratio
    pos = QtCore.QPoint(int(round(x / ratio)), int(round((tab.canvas.figure.bbox.height - y) / ratio)))
    qtbot.mouseMove(tab.canvas, pos)
    if button:
        qtbot.mouseClick(tab.canvas, QtCore.Qt.LeftButton, pos=pos)


def test_hover_names_the_production_and_click_moves_time(tab, qtbot, curves):
    target = curves[1]  # spk1_ka, train 2
    k = 15  # the peak of the sine² curve
    seen = []
    tab.frameSelected.connect(lambda rec, t: seen.append((rec, t)))
    _click_at(tab, qtbot, target, k)
    assert "production 2.2 (spk1_ka)" in tab.hover_label.text()
    assert seen == [("spk1_ka", pytest.approx(target.times[k]))]
    assert tab.state.time == pytest.approx(target.times[k])
    assert tab.picked[0] is target and tab.picked[1] == k


def test_click_on_another_recording_does_not_move_time(tab, qtbot, curves):
    ends = []
    tab.morphEndPicked.connect(lambda which, rec, t: ends.append((which, rec, t)))
    target = curves[7]  # spk1_la
    _click_at(tab, qtbot, target, 15)
    assert tab.state.time == 0.0  # the app shows spk1_ka
    tab.to_target.click()
    assert ends == [("target", "spk1_la", pytest.approx(target.times[15]))]


def test_absolute_time_axis(tab, curves):
    tab.normalised.setChecked(False)
    x = tab.lines[0].get_xdata()
    np.testing.assert_allclose(x, curves[0].time_s)
    assert "seconds" in tab.axes.get_xlabel() or "(s)" in tab.axes.get_xlabel()


def test_add_recordings_simulates_in_the_background(qtbot):
    from tests.analysis.energy_support import MODES, box_tongue
    from tonguevis.gui.energy_tab import EnergyTab
    from tonguevis.paths import DATA_DIR

    widget = EnergyTab(model_provider=box_tongue, settings=RunSettings(modes=MODES, landmarks="rule"))
    qtbot.addWidget(widget)
    loaded = []
    widget.motionsLoaded.connect(loaded.append)
    with qtbot.waitSignal(widget.motionsLoaded, timeout=90_000):
        widget.load_paths([DATA_DIR / "spk2_ka.tsv"])
    assert list(loaded[0]) == ["spk2_ka"]
    assert len(widget.curves) == 15 and {c.speaker for c in widget.curves} == {"spk2"}
    assert len(widget.lines) == 15 and widget.add_button.isEnabled()
    widget.load_paths([DATA_DIR / "missing.tsv"])
    assert "Cannot add" in widget.hover_label.text()


def test_add_motion_of_the_app(qtbot, curves):
    from types import SimpleNamespace

    from tonguevis.gui.energy_tab import EnergyTab

    widget = EnergyTab()
    qtbot.addWidget(widget)
    widget.set_curves(curves)
    times = np.arange(0, 10, 0.01)
    motion = SimpleNamespace(times=times, energy=np.cos(times) ** 2)
    prods = [SimpleNamespace(train=1, index=k, start=5 + 0.3 * k, end=5.3 + 0.3 * k, release=5 + 0.3 * k)
             for k in (2, 3, 4)]
    got = []
    widget.motionsLoaded.connect(got.append)
    widget.add_motion("spk3_ra.tsv", motion, prods)
    assert got and got[-1]["spk3_ra"] is motion
    new = [c for c in widget.curves if c.recording == "spk3_ra"]
    assert len(new) == 3 and {(c.speaker, c.syllable) for c in new} == {("spk3", "ra")}
    assert len(widget.curves) == len(curves) + 3
    widget.add_motion("spk3_ra.tsv", motion, prods[:1])  # replaces, not duplicates
    assert len([c for c in widget.curves if c.recording == "spk3_ra"]) == 1
