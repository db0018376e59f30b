"""The Measures tab (issue 35): the open recording's productions' measures, the STI of those selected."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

pytest.importorskip("PySide6")

from tests.gui.conftest import demo_session  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


@pytest.fixture
def tab(qtbot, window):
    from tonguevis.gui.measures_tab import MeasuresTab

    widget = MeasuresTab(window.state)
    window.register_tab("Measures", widget)
    with qtbot.waitSignal(widget.measured, timeout=60000) as blocker:  # measured in the job runner
        window.state.set_session(demo_session(), "primary", window)
    assert blocker.args[0] is widget.result is not None
    window.tabs.setCurrentWidget(widget)
    qtbot.waitExposed(widget)
    return widget


def _column(tab, key):
    from tonguevis.gui.measures_tab import COLUMNS

    c = [k for k, _ in COLUMNS].index(key)
    return [tab.table.item(r, c).text() for r in range(tab.table.rowCount())]


def test_the_tab_shows_the_sessions_measures_and_follows_the_palate(qtbot, tab):
    from tonguevis.workflows.measures import measure_table, measurement_palate

    session = tab.session
    assert tab.table.rowCount() == len(session.production_table) > 0
    expected = measure_table(session.recording, session.production_table,
                             measurement_palate(session.recording, "generic")).rows
    degrees = [row["constriction_degree_mm"] for row in expected]
    assert [row["constriction_degree_mm"] for row in tab.result.rows] == pytest.approx(degrees, abs=1e-9)
    shown = [float(t) for t in _column(tab, "constriction_degree_mm")]
    assert shown == pytest.approx(degrees, abs=0.0051)  # shown to 0.01 mm
    assert all(d > 0 for d in shown)  # the demo's tip stays under the generic palate
    assert "generic palate" in tab.palate_box.currentText()
    with qtbot.waitSignal(tab.measured, timeout=60000):
        tab.palate_box.setCurrentIndex(tab.palate_box.findData("none"))
    assert set(_column(tab, "constriction_degree_mm")) == {"–"}
    with qtbot.assertNotEmitted(tab.measured):  # new run settings keep the choice and measure nothing anew
        tab.state.change_run_settings(modes=12)
    assert tab.palate_box.currentData() == "none"
    assert _column(tab, "peak_velocity_closing_mm_s")[0] != "–"  # the rest does not need a palate


def test_selected_productions_give_their_sti_and_averages(qtbot, tab):
    from PySide6.QtCore import QItemSelectionModel

    every = tab.result.repetitions
    assert "STI over all" in tab.sti_label.text() and f"{every.n} productions" in tab.sti_label.text()
    model = tab.table.selectionModel()
    for row in (0, 2):
        model.select(tab.table.model().index(row, 0),
                     QItemSelectionModel.SelectionFlag.Select | QItemSelectionModel.SelectionFlag.Rows)
    assert tab.selected_rows() == [0, 2]
    chosen = tab.selected_repetitions()
    assert chosen.n == 2 and "the selected 2 productions" in tab.sti_label.text()
    assert chosen.sti["TT"] == pytest.approx(every.subset([0, 2]).sti["TT"])
    assert chosen.sti["TT"] != pytest.approx(every.sti["TT"])  # another set, another figure
    assert f"TT {chosen.sti['TT']:.2f}" in tab.sti_label.text()
    assert tab.isVisible() and not tab._figure_stale  # drawn while shown
    lines = [line for ax in tab.canvas.figure.axes for line in ax.get_lines()]
    assert lines and np.allclose(lines[0].get_ydata(), chosen.records_mm[chosen.sensors[0]].mean(axis=0))


def test_double_click_seeks_to_the_closure_and_save_writes_the_table(qtbot, tab, tmp_path, monkeypatch):
    from PySide6.QtWidgets import QFileDialog

    tab.table.cellDoubleClicked.emit(1, 0)
    closure = tab.result.rows[1]["closure_s"]
    assert math.isfinite(closure) and tab.state.time == pytest.approx(closure, abs=tab.state.frame_period)
    out = tmp_path / "measures.csv"
    monkeypatch.setattr(QFileDialog, "getSaveFileName", lambda *a, **k: (str(out), ""))
    assert tab.ask_save() == out
    rows = list(csv.DictReader(open(out)))
    assert len(rows) == tab.table.rowCount()
    assert [float(r["closure_s"]) for r in rows] == pytest.approx([r["closure_s"] for r in tab.result.rows], abs=1e-4)


def test_the_apps_tabs_include_measures(qtbot, window):
    from tonguevis.gui.tabs import add_feature_tabs

    add_feature_tabs(window)
    tab = window.feature_tabs["Measures"]
    with qtbot.waitSignal(tab.measured, timeout=60000):
        window.state.set_session(demo_session(), "primary", window)
    assert tab.table.rowCount() == len(window.session.production_table)
    assert not tab.isVisible() and tab._figure_stale and not tab.canvas.figure.axes  # hidden: not drawn yet
    window.tabs.setCurrentWidget(tab)
    qtbot.waitExposed(tab)
    assert not tab._figure_stale and tab.canvas.figure.axes  # drawn once shown


def test_a_newer_request_wins_over_a_running_one(qtbot, tab):
    """Switching the palate twice quickly shows the last choice's figures, never the first's."""
    from PySide6.QtCore import QCoreApplication

    generic = [row["constriction_degree_mm"] for row in tab.result.rows]
    tab.palate_box.setCurrentIndex(tab.palate_box.findData("none"))
    with qtbot.waitSignal(tab.measured, timeout=60000) as blocker:
        tab.palate_box.setCurrentIndex(tab.palate_box.findData("generic"))
    qtbot.wait(200)
    QCoreApplication.processEvents()
    assert blocker.args[0] is tab.result
    assert [row["constriction_degree_mm"] for row in tab.result.rows] == pytest.approx(generic)
    shown = tab.result
    with qtbot.assertNotEmitted(tab.measured):  # a result for what was asked before is dropped
        tab._on_measured(object(), ("an earlier request",))
    assert tab.result is shown


def test_simulated_against_a_palate_each_production_has_its_palatogram_at_the_closure(qtbot, window, tmp_path):
    """Issue 36, item 4: the productions table gives each production's palatogram at its closure (the percentage,
    CoG, anteriority and posteriority of tonguevis.analysis.epg.production_epg on the simulated motion)."""
    from tests.gui.test_palate_contact import flat_palate
    from tonguevis.analysis.epg import production_epg
    from tonguevis.gui.measures_tab import MeasuresTab

    window.state.set_run_settings(window.state.run_settings.replace(frame="model"))
    tab = MeasuresTab(window.state)
    window.register_tab("Measures", tab)
    path = tmp_path / "roof.stl"
    flat_palate().save(path)
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        window.show_session(demo_session())
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        assert window.load_palate(path)
    session = window.session
    qtbot.waitUntil(lambda: tab.result is not None and "epg_cog" in tab.result.rows[0], timeout=60000)
    want = production_epg(session.motion, session.production_table)
    assert [row["epg_percent_contact"] for row in tab.result.rows] == pytest.approx(
        [w["epg_percent_contact"] for w in want], nan_ok=True)
    shown = _column(tab, "epg_percent_contact")
    assert len(shown) == len(want) and any(text not in ("–", "0.00") for text in shown)
