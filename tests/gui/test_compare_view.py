"""Two recordings in the app: B beside A (one camera) or as a ghost in A's views, one transport,
productions lined up by normalised time, the distance between the tongues as a colouring."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import DEMO, crop, demo_session, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(180)]


def other_session(path_name: str = "spk2_ta.tsv", start: float = 3.0, end: float = 8.0):
    """Another demo speaker's /ta/ (a different rate), cut to its first train."""
    from tonguevis.workflows.session import load_session, make_session

    path = DEMO.with_name(path_name)
    if not path.exists():
        pytest.skip(f"demo corpus not built: {path}")
    return make_session(crop(load_session(path).recording, start, end), path)


def compare(qtbot, window, session, **options):
    with qtbot.waitSignal(window.compare_finished, timeout=60000) as blocker:
        window.compare_session(session, **options)
    assert blocker.args == [True], window.state.status
    qtbot.waitUntil(lambda: window.compare_panel.comparison is not None, timeout=5000)
    return window.compare_panel


@pytest.fixture
def pair(qtbot, window):
    a = show_and_simulate(qtbot, window, demo_session())
    b = other_session()
    panel = compare(qtbot, window, b)
    return window, a, b, panel


def test_one_transport_drives_both_and_productions_line_up(qtbot, pair):
    from tonguevis.analysis.compare import match_frames

    window, a, b, panel = pair
    assert panel.isVisible() and panel.comparison.mode == "production"
    assert len(a.productions) >= 2 and len(b.productions) >= 2
    reference = match_frames(a.motion.times, b.motion.times, panel.comparison.productions_a,
                             panel.comparison.productions_b)
    for k in (0, len(reference) // 3, len(reference) - 1):  # moments inside the paired productions
        before = panel.renders
        window.state.set_time(float(a.motion.times[reference.frames_a[k]]))
        assert panel.frame_b == reference.frames_b[k] and panel.renders == before + 1
        assert window.view3d.frame == reference.frames_a[k]  # A moved with the same transport
    # the middle of A's second production shows the middle of B's second one, whatever the rates
    (sa, ea), (sb, eb) = a.productions[1], b.productions[1]
    window.state.set_time(0.5 * (sa + ea))
    assert abs(b.motion.times[panel.frame_b] - 0.5 * (sb + eb)) <= 0.011
    assert "production 2, 50 % through" in panel.caption.text()


def test_absolute_time_shows_b_at_the_same_moment(qtbot, pair):
    window, a, b, panel = pair
    panel.set_time_mode("absolute")
    assert panel.comparison.mode == "absolute"
    t = 5.0
    window.state.set_time(t)
    expected = int(np.argmin(np.abs(b.motion.times - a.motion.times[a.frames.frame_at(t)])))
    assert panel.frame_b == expected


def test_side_by_side_views_share_one_camera(qtbot, pair):
    window, _a, _b, panel = pair
    camera_a = window.view3d.plotter.renderers[0].GetActiveCamera()
    assert panel.plotter.renderer.GetActiveCamera() is camera_a  # turning either turns both
    assert panel.plotter.interactor.isVisible()
    before = panel.plotter.renderer.GetActiveCamera().GetPosition()
    camera_a.Azimuth(30)
    assert panel.plotter.renderer.GetActiveCamera().GetPosition() != before


def test_ghost_draws_b_translucent_in_each_of_a_views(qtbot, pair):
    window, _a, b, panel = pair
    panel.set_layout("ghost")
    assert window.state.compare_view.layout == "ghost"  # the layout is the app model's
    renderers = window.view3d.plotter.renderers
    ghosts = window.view3d.ghosts  # A's view draws B's ghost itself, from the model's comparison
    assert len(ghosts) == len(renderers) == 4
    from tonguevis.render.surface_geometry import hidden_side
    from tonguevis.render.scene import surface_faces

    # B's tongue is closed: the ghost is its near wall only (both walls, blended in triangle
    # order, showed the triangles as patches).
    hidden = hidden_side(np.asarray(b.frames.points[0]), surface_faces(b.motion.model))
    assert hidden in ("back", "front")
    for renderer, ghost in zip(renderers, ghosts):
        assert renderer.HasViewProp(ghost) and ghost.GetVisibility() and ghost.prop.opacity < 0.5
        assert (ghost.prop.GetBackfaceCulling(), ghost.prop.GetFrontfaceCulling()) == (hidden == "back", hidden == "front")
    assert not panel.plotter.interactor.isVisible()
    window.state.set_time(6.0)
    j = panel.frame_b
    np.testing.assert_allclose(panel._surface.points, b.frames.points[j] + b.motion.jaw_offset[j].astype(np.float32),
                               atol=1e-7)  # B's head-frame shape at its matched frame
    panel.set_layout("side")
    assert not window.view3d.ghosts and not any(r.HasViewProp(g) for r, g in zip(renderers, ghosts))
    assert panel.plotter.interactor.isVisible()
    window.state.set_compare_view(None, layout="ghost")  # a script's change: the panel and A's view follow
    assert panel.layout_box.currentData() == "ghost" and len(window.view3d.ghosts) == 4


def test_difference_colouring_is_the_distance_between_the_tongues(qtbot, pair):
    window, a, b, panel = pair
    window.state.set_color("difference")
    window.state.set_time(6.1)
    i, j = window.view3d.frame, panel.frame_b
    shown = np.asarray(window.view3d.scene.surface.point_data["value"])
    nodes = a.frames.nodes  # the drawn nodes (surface and sensors)
    reference = 1e3 * panel.comparison.difference(i, j, nodes)  # float64, from q
    np.testing.assert_allclose(shown[nodes], reference, atol=2e-3)  # float32 drawing data, mm
    assert shown[nodes].max() > 0.05  # two speakers: the tongues differ
    np.testing.assert_allclose(panel._b_values, shown, atol=1e-6)  # B coloured by the same distances
    assert window.view3d.scene.mode == "difference"
    assert " ".join(window.view3d.scene.scalar_bar.GetTitle().split()).startswith("distance to")  # wrapped to the view


def _lit_b(panel):
    """B's drawn colours (m, 3) uint8 at its surface nodes after the panel's view rendered."""
    panel.plotter.render()
    return np.asarray(panel._surface.point_data["rgb"])[panel._b_nodes].copy()


def test_b_is_lit_and_coloured_like_a_by_default(qtbot, pair):
    """Without any option B is drawn as A is: A's colouring through A's colour map, lit by A's lights."""
    from tonguevis.render.scene import LIGHTS, TONGUE_COLOUR, TONGUE_MATERIAL, mapped_colours
    from tonguevis.render.shading import shade

    window, _a, b, panel = pair
    assert window.state.color == "displacement"
    window.state.set_time(5.62)
    j, nodes = panel.frame_b, panel._b_nodes
    assert not panel._b_actor.prop.lighting  # drawn from colours lit at the vertices, as A's tongue
    # coloured: B's displacement (mm) at its matched frame through A's lookup table (A's range)
    values = b.frames.scalars["displacement"][j][nodes]
    lut = window.view3d.scene.lookup_table
    np.testing.assert_allclose(panel.b_colours(), mapped_colours(lut, values))
    assert np.ptp(panel.b_colours(), axis=0).max() > 0.15  # not one flat colour (the map starts at plasma 0.25)
    # lit: VTK's lighting model for A's lights and material, for the camera both views share
    rgb = _lit_b(panel)
    camera = panel.plotter.renderer.GetActiveCamera()
    view = np.array(camera.GetViewTransformMatrix().GetData()).reshape(4, 4)
    points = np.asarray(panel._surface.points)[nodes]
    normals = np.asarray(panel._surface.point_data["Normals"])[nodes]
    expected = shade(panel.b_colours(), normals, points, view, LIGHTS, parallel=camera.GetParallelProjection(),
                     **TONGUE_MATERIAL)
    np.testing.assert_array_equal(rgb, expected)
    # the light follows the camera: turning it relights B
    camera.Azimuth(60)
    assert np.abs(_lit_b(panel).astype(int) - rgb).max() > 20
    # plain: the tongue's own colour, still lit (shaded from light to dark, not a silhouette)
    window.state.set_color("plain")
    import pyvista as pv

    np.testing.assert_allclose(panel.b_colours()[0], pv.Color(TONGUE_COLOUR).float_rgb)
    plain = _lit_b(panel).astype(float).sum(axis=1)
    assert plain.max() - plain.min() > 150


def test_the_energy_tab_gets_both_recordings(qtbot, window):
    from tonguevis.gui.tabs import add_feature_tabs

    add_feature_tabs(window)
    show_and_simulate(qtbot, window, demo_session())
    compare(qtbot, window, other_session())
    names = set(window.state.motions)
    assert any("spk1_ta" in n for n in names) and any("spk2_ta" in n for n in names), names


def test_stop_comparing_hides_the_panel_and_the_difference_colouring(qtbot, pair):
    window, _a, _b, panel = pair
    window.state.set_color("difference")
    window.stop_comparing()
    assert not panel.isVisible() and panel.comparison is None
    assert not window.compare_panel.difference_shown and window.state.color == "displacement"


def test_a_recording_compared_with_itself_under_the_linear_model(qtbot, window):
    a = show_and_simulate(qtbot, window, demo_session())
    panel = compare(qtbot, window, demo_session(), warping=False)
    b = window.state.session_of("compare")
    assert a.motion.warping and not b.motion.warping
    window.state.set_time(6.1)
    assert panel.frame_b == window.view3d.frame  # the same recording: the same frame
    difference = panel.comparison.difference(window.view3d.frame, panel.frame_b)
    assert 0 < difference.max() < 5e-3  # warping changes the shape a little, not centimetres


def test_a_bad_file_to_compare_is_a_dialog_and_a_is_kept(qtbot, window, tmp_path):
    a = show_and_simulate(qtbot, window, demo_session())
    bad = tmp_path / "broken.tsv"
    bad.write_text("not an EMA file\n1\t2\n")
    assert not window.open_compare(bad)
    assert "broken.tsv" in window.state.status and window.last_dialog is not None
    assert window.state.session_of("compare") is None and window.session is a
    assert not window.compare_panel.isVisible()


def test_closing_b_while_it_simulates_stops_its_job(qtbot, window):
    show_and_simulate(qtbot, window, demo_session())
    window.compare_session(other_session())
    job = window.compare_job
    assert job is not None and job.isRunning()
    window.compare_panel.close_button.click()  # the panel's own button: through the app model
    assert window.compare_job is None and not job.isRunning()
    assert window.state.session_of("compare") is None and not window.compare_panel.isVisible()
    qtbot.wait(200)  # a late result would be ignored, and none comes
    assert window.state.session_of("compare") is None


def test_b_without_productions_is_compared_on_absolute_time_and_says_so(qtbot, window):
    show_and_simulate(qtbot, window, demo_session())
    rest_only = other_session(start=0.0, end=3.0)  # before the first train: no production
    assert not rest_only.productions
    panel = compare(qtbot, window, rest_only)
    assert panel.comparison.mode == "absolute" and "absolute time" in panel.note
    window.state.set_time(1.0)
    assert "on absolute time" in panel.caption.text()


@pytest.mark.parametrize("layout", ["ghost", "side"])
def test_during_playback_b_is_drawn_for_the_frame_a_draws(qtbot, pair, layout):
    """Playback draws A a frame ahead of the clock (for the moment it is painted): B, as a ghost
    in A's views or in its own view, is drawn for A's frame in every render, never for the clock."""
    window, a, b, panel = pair
    panel.set_layout(layout)
    state, view3d = window.state, window.view3d
    state.set_time(float(a.productions[0][0]))
    qtbot.wait(200)
    seen = []
    times_a = a.frames.times

    def rendered(*_args) -> None:
        if state.playing:
            seen.append((panel.frame_b, panel.matched_frame(float(times_a[view3d.frame])), state.time,
                         float(times_a[view3d.frame])))

    render_window = (view3d.plotter if layout == "ghost" else panel.plotter).render_window
    observer = render_window.AddObserver("StartEvent", rendered)
    state.set_playing(True)
    qtbot.waitUntil(lambda: state.time > a.productions[0][0] + 0.8, timeout=15000)
    state.set_playing(False)
    render_window.RemoveObserver(observer)
    assert len(seen) > 5
    assert all(shown == matched for shown, matched, _, _ in seen), seen
    if hasattr(view3d.plotter, "set_pipelined"):  # image views: A is drawn ahead of the clock
        assert np.median([drawn - clock for _, _, clock, drawn in seen]) > 0.0
    assert panel.frame_b == panel.matched_frame(float(times_a[a.frames.frame_at(state.time)]))


def test_a_production_b_does_not_have_is_said_so(qtbot, window):
    """B with fewer productions than A: in A's later productions the caption says B has none there."""
    a = show_and_simulate(qtbot, window, demo_session())
    short = other_session(start=3.0, end=6.0)  # B cut short: 3 productions to A's 5
    panel = compare(qtbot, window, short)
    assert panel.comparison.mode == "production"
    n_b = len(short.productions)
    assert 1 <= n_b < len(a.productions)
    start, end = a.productions[n_b]  # A's production n_b + 1: B has no such production
    window.state.set_time(start + 0.34 * (end - start))
    caption = panel.caption.text()
    assert f"B has no production {n_b + 1} (it has {n_b})" in caption
    assert "(both)" not in caption
    assert panel.frame_b == len(short.motion.times) - 1  # B's recording ended 0.1 s into A's production 4
    assert "held on its last frame" in caption
    # in a production both have, the caption still says "both"
    start, end = a.productions[0]
    window.state.set_time(0.5 * (start + end))
    assert "production 1, 50 % through (both)" in panel.caption.text()
