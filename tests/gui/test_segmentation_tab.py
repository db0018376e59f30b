"""The Segmentation tab: runs in a worker, colours partitions, closes interfaces with constraint modes,
cancels, picks seeds, and says why it cannot run."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import demo_session, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


def _add_tab(window):
    from tonguevis.gui.segmentation_tab import SegmentationTab

    tab = SegmentationTab(window.state)  # it follows the window's app model itself
    window.register_tab("Segmentation", tab)
    assert window.segmentation_tab is tab
    return tab


@pytest.fixture
def tab(qtbot, window):
    widget = _add_tab(window)
    show_and_simulate(qtbot, window, demo_session())
    window.tabs.setCurrentWidget(widget)
    qtbot.waitExposed(widget)
    motion = window.session.motion
    # The frame of largest energy: a target with something to segment.
    window.state.set_time(float(motion.times[int(np.argmax(motion.energy))]))
    return widget


def _run(qtbot, tab, expected="ok"):
    with qtbot.waitSignal(tab.finished, timeout=90000) as blocker:
        tab.run()
    assert blocker.args == [expected], tab.status.text()


def _choose(box, data):
    index = box.findData(data)
    assert index >= 0
    box.setCurrentIndex(index)


def test_rigid_auto_colours_partitions_and_fills_table(qtbot, tab):
    _choose(tab.mode_box, "rigid")
    tab.threshold.setValue(1.0)
    tab.max_partitions.setValue(4)
    _run(qtbot, tab)
    result = tab.result
    assert result.mode == "rigid" and 2 <= result.n_partitions <= 4
    # The approximation is drawn on the split mesh, whose surface holds every partition's
    # faces (interfaces included): every partition shows, each in its own colour.
    approx = tab.surfaces["approximation"]
    assert len(np.unique(approx.cell_data["partition"])) == result.n_partitions
    assert len(np.unique(approx.cell_data["colour"], axis=0)) == result.n_partitions
    # The target view shows the boundary faces, each with the partition of the tet behind it.
    from tonguevis.mesh.tetmesh import TET_FACES, face_keys

    faces = result.tets[:, TET_FACES].reshape(-1, 3)
    _, inverse, counts = np.unique(face_keys(faces), return_inverse=True, return_counts=True)
    owners = np.repeat(np.arange(len(result.tets)), 4)[counts[inverse.ravel()] == 1]
    target = tab.surfaces["target"]
    assert target.n_cells == len(owners)
    assert sorted(np.asarray(target.cell_data["tet"]).tolist()) == sorted(owners.tolist())
    shown = np.asarray(target.cell_data["partition"])
    np.testing.assert_array_equal(shown, result.labels[np.asarray(target.cell_data["tet"])])
    assert len(np.unique(target.cell_data["colour"], axis=0)) == len(np.unique(shown)) >= 2
    # The left view is the target shape at the cursor frame.
    motion = tab.session.motion
    frame = motion.frame_at(tab.state.time)
    ids = np.asarray(target.point_data["vtkOriginalPointIds"])
    np.testing.assert_allclose(target.points, (motion.model.mesh.points + motion.displacement(frame))[ids],
                               atol=1e-9)
    # One table line per partition, with the tets adding up, and the global error.
    lines = tab.table.toPlainText().splitlines()
    rows = [line.split() for line in lines[1:1 + result.n_partitions]]
    assert sum(int(r[1]) for r in rows) == len(result.tets)
    assert f"{100 * result.relative_error:.2f} %" in lines[-1]
    # Rigid pieces do not meet: some interface node copies are drawn apart.
    assert _copy_spread(approx) > 1e-6
    # Colour by local error: the approximation shows sqrt(e_E) in mm of the tet behind each face,
    # with a scalar bar; the target stays coloured by partition.
    _choose(tab.colour_box, "error")
    surface = tab.surfaces["approximation"]
    tets = np.asarray(surface.cell_data["tet"])
    np.testing.assert_allclose(surface.cell_data["error_mm"], 1000 * np.sqrt(result.element_errors[tets]))
    assert tab.surfaces["approximation_actor"].mapper.GetArrayName() == "error_mm"
    assert tab.surfaces["target_actor"].mapper.GetArrayName() == "colour"
    assert list(tab.plotter.scalar_bars.keys()) == ["local error sqrt(e_E), mm"]


def _copy_spread(approx) -> float:
    """Largest distance between two drawn copies of one mesh node (0 when interfaces close)."""
    nodes = np.asarray(approx.point_data["node"])
    points = np.asarray(approx.points)
    order = np.argsort(nodes, kind="stable")
    nodes, points = nodes[order], points[order]
    same = nodes[1:] == nodes[:-1]
    return float(np.linalg.norm(points[1:][same] - points[:-1][same], axis=1).max()) if same.any() else 0.0


def test_constraint_interfaces_equal_the_target(qtbot, tab):
    _choose(tab.mode_box, "constraint")
    tab.threshold.setValue(1.0)
    tab.max_partitions.setValue(3)
    _run(qtbot, tab)
    result = tab.result
    assert result.mode == "constraint" and result.n_partitions >= 2
    approx = tab.surfaces["approximation"]
    nodes = np.asarray(approx.point_data["node"])
    # Interface nodes: nodes of tets in two partitions.
    owners = [set() for _ in range(len(result.points))]
    for tet, label in zip(result.tets, result.labels):
        for n in tet:
            owners[n].add(int(label))
    interface = np.array([len(o) > 1 for o in owners])
    drawn = interface[nodes]
    assert drawn.sum() > 0
    target = result.target_points()[nodes[drawn]]
    np.testing.assert_allclose(approx.points[drawn], target, atol=1e-9)
    assert _copy_spread(approx) < 1e-9  # the pieces meet: no gap anywhere


def test_cancel_leaves_the_tab_usable(qtbot, tab):
    tab.max_partitions.setValue(3)
    with qtbot.waitSignal(tab.finished, timeout=90000) as blocker:
        tab.run()
        tab.cancel()
    assert blocker.args == ["cancelled"]
    assert tab.result is None and tab.run_button.isEnabled()
    _run(qtbot, tab)
    assert tab.result is not None and tab.table.toPlainText()
    # A newly simulated motion drops the result of the old one ...
    import copy
    from dataclasses import replace

    session = tab.session
    tab.set_session(session)  # the same motion again (e.g. the window republishing): kept
    assert tab.result is not None
    tab.set_session(replace(session, motion=copy.copy(session.motion)))
    assert tab.result is None and not tab.table.toPlainText()
    assert tab.surfaces["target"].n_cells > 0  # the new motion's frame is shown, ready for seeds
    # ... and a run that ends after its motion was replaced is discarded.
    with qtbot.waitSignal(tab.finished, timeout=90000):
        tab.run()
        tab.set_session(session)
    assert tab.result is None and "discarded" in tab.status.text()


def test_picked_seeds_grow_their_partitions(qtbot, tab):
    _choose(tab.mode_box, "rigid")
    # Before any run the left view shows the current frame, so seeds can be picked at once.
    surface = tab.surfaces["target"]
    motion = tab.session.motion
    assert surface.n_cells > 0
    frame = motion.frame_at(tab.state.time)
    ids = np.asarray(surface.point_data["vtkOriginalPointIds"])
    np.testing.assert_allclose(surface.points, (motion.model.mesh.points + motion.displacement(frame))[ids],
                               atol=1e-9)
    faces = [0, surface.n_cells - 1]
    picked = [tab.pick_cell(face) for face in faces]
    assert picked == [int(surface.cell_data["tet"][f]) for f in faces] and picked[0] != picked[1]
    assert tab.seeds == picked and tab.seeding_box.currentData() == "picked"
    assert str(picked[0]) in tab.seeds_label.text()
    assert tab.pick_cell(10 ** 9) is None and len(tab.seeds) == 2
    # The picked seeds are marked in the left view.
    assert tab.plotter.renderers[0].actors["picked seeds"].GetMapper().GetInput().GetNumberOfPoints() == 2
    _run(qtbot, tab)
    assert tab.result.n_partitions == 2
    assert sorted(tab.result.seeds.tolist()) == sorted(picked)
    assert tab.result.labels[picked[0]] != tab.result.labels[picked[1]]
    tab.clear_seeds()
    assert tab.seeds == [] and "picked seeds" not in tab.plotter.renderers[0].actors


def test_errors_open_a_dialog(qtbot, window):
    from tonguevis.gui.tabs import add_feature_tabs

    add_feature_tabs(window)  # the app's wiring adds the tab
    tab = window.segmentation_tab
    assert window.tabs.indexOf(tab) >= 0 and window.tabs.tabText(window.tabs.indexOf(tab)) == "Segmentation"
    tab.run()  # nothing open yet
    assert tab.last_dialog is not None and "no simulated motion" in tab.last_dialog.text()
    assert tab.result is None and tab.run_button.isEnabled()
    tab.last_dialog.close()
    # Picked seeds without any seed.
    show_and_simulate(qtbot, window, demo_session())
    _choose(tab.seeding_box, "picked")
    tab.run()
    assert "no seeds picked" in tab.last_dialog.text()
    tab.last_dialog.close()
    # A production target with the cursor outside every production.
    _choose(tab.target_box, "production")
    window.state.set_time(window.session.motion.times[0])
    tab.run()
    assert "no production under the cursor" in tab.last_dialog.text()
    tab.last_dialog.close()


def test_click_in_pick_mode_adds_the_tet_under_the_mouse(qtbot, tab):
    tab.pick_button.setChecked(True)
    renderer = tab.plotter.renderers[0]
    tab.plotter.render()
    # Click the middle of the left view, where the tongue is.
    width, height = tab.plotter.render_window.GetSize()
    x0, y0, x1, y1 = renderer.GetViewport()
    x, y = int((x0 + x1) / 2 * width), int((y0 + y1) / 2 * height)
    tab.plotter.iren.interactor.SetEventPosition(x, y)
    tab._on_click()
    assert len(tab.seeds) == 1
    surface = tab.surfaces["target"]
    assert tab.seeds[0] in set(np.asarray(surface.cell_data["tet"]).tolist())
    # The picked tet is under the mouse: the surface point the depth buffer finds there
    # (an independent picker) lies in it (barycentric coordinates >= 0, up to the z-buffer's precision).
    import vtk

    world = vtk.vtkWorldPointPicker()
    world.Pick(x, y, 0, renderer)
    hit = np.array(world.GetPickPosition())
    motion = tab.session.motion
    points = motion.model.mesh.points + motion.displacement(motion.frame_at(tab.state.time))
    corners = points[motion.model.mesh.tets[tab.seeds[0]]]
    weights = np.linalg.solve(np.vstack([corners.T, np.ones(4)]), np.append(hit, 1.0))
    assert weights.min() > -0.05, weights
    tab.pick_button.setChecked(False)
    tab.plotter.iren.interactor.SetEventPosition(x + 5, y)
    assert tab._pick_observer is None


def test_exaggerated_displacements_widen_rigid_gaps(qtbot, tab):
    _choose(tab.mode_box, "rigid")
    tab.threshold.setValue(1.0)
    tab.max_partitions.setValue(3)
    _run(qtbot, tab)
    result = tab.result
    gap = _copy_spread(tab.surfaces["approximation"])
    _choose(tab.scale_box, 5.0)
    # Both shapes are drawn with five times the displacement; rigid gaps grow five-fold.
    target = tab.surfaces["target"]
    ids = np.asarray(target.point_data["vtkOriginalPointIds"])
    np.testing.assert_allclose(target.points, (result.points + 5 * result.target[result.peak_frame])[ids],
                               atol=1e-9)
    assert _copy_spread(tab.surfaces["approximation"]) == pytest.approx(5 * gap, rel=1e-6)
    # Seed markers sit at the seed tets' centres of the drawn shape.
    markers = tab.plotter.renderers[0].actors["result seeds"].GetMapper().GetInput()
    drawn = np.array([markers.GetPoint(i) for i in range(markers.GetNumberOfPoints())])
    expected = (result.points + 5 * result.target[result.peak_frame])[result.tets[result.seeds]].mean(axis=1)
    np.testing.assert_allclose(drawn, expected, atol=1e-9)
