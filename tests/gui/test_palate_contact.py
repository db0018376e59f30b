"""The app in the head frame, against a palate: the jaw moves the tongue, a palate file re-simulates with
contact, a bad one gives a dialog, contact is coloured, the midline plot follows the cursor, exports say which frame."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import demo_session, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(180)]

#: The test palate: a flat roof this far above the block tongue's top (z = 0), in the model frame.
ROOF_MM = 3.0


@pytest.fixture(autouse=True)
def _in_the_model_frame(request):
    """These palates are built in the block model's own frame (``ROOF_MM`` above its top) and checked there:
    the app simulates in the model frame here (its default, the speaker's, places the model and a
    model-frame palate with it by the rest alignment: tests/test_speaker_frame.py)."""
    if "window" in request.fixturenames:
        window = request.getfixturevalue("window")
        window.state.set_run_settings(window.state.run_settings.replace(frame="model"))


def flat_palate(height_mm: float = ROOF_MM, frame: str | None = "model"):
    """A flat palate z = height over the block model (x -80..10 mm, y -30..30 mm)."""
    from tonguevis.palate import PalateSurface

    x = np.arange(-0.08, 0.0101, 0.001)
    y = np.arange(-0.03, 0.0301, 0.001)
    meta = {} if frame is None else {"frame": frame}
    return PalateSurface(x, y, np.full((len(y), len(x)), 1e-3 * height_mm), metadata=meta)


def simulate_with_palate(qtbot, window, path, session=None, timeout=120000):
    """Show the demo, then File ▸ Load palate ``path``: wait for the re-simulation."""
    session = session or show_and_simulate(qtbot, window, demo_session())
    with qtbot.waitSignal(window.simulation_finished, timeout=timeout) as blocker:
        assert window.load_palate(path)
    assert blocker.args == [True], window.statusBar().currentMessage()
    return session


def strongest_jaw_frame(session) -> int:
    return int(np.argmax(np.linalg.norm(session.motion.jaw_offset, axis=1)))


def test_head_frame_moves_the_tongue_and_jaw_by_the_jaw_offset_and_the_toggle_removes_it(qtbot, window):
    session = show_and_simulate(qtbot, window, demo_session())
    frames, view, scene = session.frames, window.view3d, window.view3d.scene
    i = strongest_jaw_frame(session)
    offset = session.motion.jaw_offset[i]
    assert np.linalg.norm(offset) > 3e-3  # the demo's jaw opens by millimetres
    assert window.state.reference == "head" and window.reference_actions["head"].isChecked()
    window.state.set_time(float(frames.times[i]))
    jaw_rest = scene._context_rest["jaw"]
    palate_rest = scene._context_rest["palate"]
    # Head frame: the tongue, its sensors and the jaw carried by the jaw's translation, the palate fixed.
    np.testing.assert_allclose(scene.surface.points, frames.points[i] + offset, atol=1e-6)
    np.testing.assert_allclose(scene.sensors.points, frames.sensor_points[i] + offset, atol=1e-6)
    np.testing.assert_allclose(scene.context["jaw"].points, jaw_rest + offset, atol=1e-6)
    np.testing.assert_allclose(scene.context["palate"].points, palate_rest, atol=1e-7)
    assert "head frame" in view.drawn.caption and "head frame" in scene.time_text.GetText(2)
    assert "head frame" in window.frame_status.text()
    assert all("head frame" in label.GetText(2) for label in scene.view_labels.values())
    surface_id = id(scene.surface)
    # View ▸ Jaw frame: the tongue and jaw as simulated, the palate moving by minus the jaw's translation.
    window.reference_actions["jaw"].trigger()
    assert window.state.reference == "jaw" and view.reference.currentData() == "jaw"
    np.testing.assert_allclose(scene.surface.points, frames.points[i], atol=1e-6)
    np.testing.assert_allclose(scene.context["jaw"].points, jaw_rest, atol=1e-7)
    np.testing.assert_allclose(scene.context["palate"].points, palate_rest - offset, atol=1e-6)
    assert id(scene.surface) == surface_id  # moved in place, not rebuilt
    assert "jaw frame" in view.drawn.caption and "jaw frame" in window.frame_status.text()
    assert all("jaw frame" in label.GetText(2) for label in scene.view_labels.values())
    # The toolbar's combo box steers the same state.
    view.reference.setCurrentIndex(view.reference.findData("head"))
    assert window.state.reference == "head" and window.reference_actions["head"].isChecked()
    np.testing.assert_allclose(scene.surface.points, frames.points[i] + offset, atol=1e-6)


def test_the_analysis_tabs_say_they_are_in_the_jaw_frame(qtbot, window):
    from tonguevis.render.segmentation_view import frame_caption
    from tonguevis.gui.tabs import add_feature_tabs

    add_feature_tabs(window)
    assert "jaw frame" in window.energy_tab.frame_label.text()
    assert "jaw frame" in frame_caption(1.0)


def test_loading_a_palate_resimulates_with_contact_and_replaces_the_surface(qtbot, window, tmp_path):
    from tonguevis.palate import PalateSurface

    path = tmp_path / "roof.stl"
    flat_palate().save(path)
    session = show_and_simulate(qtbot, window, demo_session())
    assert session.motion.penetration is None and session.shown_palate.generic  # no contact: generic, drawn only
    generic_points = np.array(window.view3d.scene.context["palate"].points)
    simulate_with_palate(qtbot, window, path, session)
    motion = session.motion
    assert isinstance(window.palate, PalateSurface) and window.palate.metadata["file"] == str(path)
    assert motion.penetration is not None and "contact" in motion.metadata
    contact = motion.metadata["contact"]
    assert contact["frames_in_contact"] > 0 and contact["contact_area_max_mm2"] > 0
    shown = session.shown_palate
    assert shown.simulated and not shown.generic and "roof.stl" in shown.label
    drawn = np.array(window.view3d.scene.context["palate"].points)
    assert drawn.shape != generic_points.shape or not np.allclose(drawn, generic_points)
    np.testing.assert_allclose(drawn, shown.points, atol=1e-7)  # the head frame: the palate where it is
    np.testing.assert_allclose(drawn[:, 2], 1e-3 * ROOF_MM, atol=1e-7)
    # Every frame in contact: the status bar and the Palate tab report the simulation's own figures.
    i = int(np.argmax(motion.contact_area))
    window.state.set_time(float(motion.times[i]))
    assert f"penetration {1e3 * motion.penetration[i]:.2f} mm" in window.frame_status.text()
    assert f"contact area {1e6 * motion.contact_area[i]:.0f} mm²" in window.frame_status.text()
    assert "deepest penetration" in window.statusBar().currentMessage()  # the simulation's summary
    # The palate stays for the next recording, and File ▸ No palate turns contact off again.
    with qtbot.waitSignal(window.simulation_finished, timeout=120000):
        window.use_no_palate()
    assert window.palate is None and session.motion.penetration is None and session.shown_palate.generic


def test_a_speakers_palate_is_placed_exactly_as_the_simulation_placed_it(qtbot, window, tmp_path, monkeypatch):
    """A palate in the recording's frame: the views draw the surface simulate() used, from the same core function."""
    import importlib

    simulate_module = importlib.import_module("tonguevis.sim.palate_placement")  # where the simulation places it
    session = show_and_simulate(qtbot, window, demo_session())
    rec = session.recording
    tt = rec.sensors["TT"]
    # A flat roof 2 mm above the highest the tongue tip went, in the recording's own frame.
    palate = flat_palate(frame=None)
    centre = np.nanmean(tt, axis=0)
    palate.x = palate.x + centre[0] + 0.02
    palate.y = palate.y + centre[1]
    palate.z = np.full_like(palate.z, np.nanmax(tt[:, 2]) + 2e-3)
    path = tmp_path / "speaker.stl"
    palate.save(path)
    placed = []
    original = simulate_module.place_palate

    def spy(*args, **kwargs):
        placed.append(original(*args, **kwargs))
        return placed[-1]

    monkeypatch.setattr(simulate_module, "place_palate", spy)
    simulate_with_palate(qtbot, window, path, session)
    assert len(placed) == 1  # by simulate() only: the views draw the surface it returned with the motion
    (used, lift, info), = placed
    assert session.shown_palate.surface is used is session.motion.palate
    assert session.shown_palate.raised_mm == pytest.approx(info.get("traced_raised_mm", 0.0))
    assert session.shown_palate.raised_mm == pytest.approx(session.motion.metadata["contact"]["palate_raised_mm"])
    # it was moved by the alignment (into the model's frame, resampled there when made whole from the speech)
    x0, x1 = used._from_own(np.array([[used.x[0], used.y[0], 0.0], [used.x[-1], used.y[-1], 0.0]]))[:, 0]
    assert abs(min(x0, x1) - palate.x[0]) > 1e-3 or abs(max(x0, x1) - palate.x[-1]) > 1e-3


@pytest.mark.parametrize("kind", ["garbage", "missing", "no_triangles", "truncated_grid", "flat_line"])
def test_a_bad_palate_file_gives_a_dialog_naming_it_and_changes_nothing(qtbot, window, tmp_path, kind):
    session = show_and_simulate(qtbot, window, demo_session(3.5, 5.5))
    motion = session.motion
    path = tmp_path / "palate.stl"
    if kind == "garbage":
        path.write_text("solid nothing\nthis is not a mesh\n")
    elif kind == "no_triangles":
        path = tmp_path / "palate.obj"
        path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\n")
    elif kind == "truncated_grid":
        flat_palate().save(path)
        grid = tmp_path / "palate.palate.npz"
        grid.write_bytes(grid.read_bytes()[:200])
    elif kind == "flat_line":  # triangles standing on edge: nothing seen from below
        path = tmp_path / "palate.obj"
        path.write_text("v 0 0 0\nv 0.01 0 0\nv 0.02 0 0.01\nf 1 2 3\n")
    assert not window.load_palate(path)
    box = window.last_dialog
    assert box is not None and box.isVisible()
    assert path.name in box.text() and "palate" in box.windowTitle().lower()
    box.close()
    assert window.palate is None and session.motion is motion  # nothing re-simulated
    window.state.set_time(5.0)  # still alive


def test_a_palate_that_does_not_fit_the_recording_keeps_what_was_shown(qtbot, window, tmp_path):
    """A palate cutting through the tongue at rest: the simulation refuses it, the dialog says which palate."""
    path = tmp_path / "low.stl"
    flat_palate(-5.0).save(path)
    session = show_and_simulate(qtbot, window, demo_session(3.5, 5.5))
    motion = session.motion
    with qtbot.waitSignal(window.simulation_finished, timeout=60000) as blocker:
        assert window.load_palate(path)
    assert blocker.args == [False]
    text = window.last_dialog.text()
    assert "cuts through the tongue" in text and "low.stl" in text and "No palate" in text
    window.last_dialog.close()
    assert window.palate is None and session.motion is motion


def test_contact_colouring_shows_a_known_contact(qtbot, window, tmp_path):
    """Against a flat roof the distance is the vertical gap: colour = roof height - node height (mm)."""
    path = tmp_path / "roof.stl"
    flat_palate().save(path)
    session = simulate_with_palate(qtbot, window, path)
    motion, frames, scene = session.motion, session.frames, window.view3d.scene
    i = int(np.argmax(motion.contact_area))
    window.state.set_color("contact")
    window.state.set_time(float(frames.times[i]))
    values = np.array(scene.surface.point_data["value"])
    head = frames.points[i] + motion.jaw_offset[i]
    np.testing.assert_allclose(values, ROOF_MM - 1e3 * head[:, 2], atol=1e-3)
    touching = values <= 0.3
    assert touching.sum() >= 3  # a patch of the tongue touches the roof in this frame
    # The colour map: touching is red, far is blue, inside the palate has its own colour, labelled on the bar.
    lut = scene.lookup_table
    red, blue = (np.array(lut.map_value(v)[:3]) for v in (0.1, 9.9))
    assert red[0] > 0.6 and red[2] < 0.3 and blue[2] > 0.5 and blue[0] < 0.4
    assert tuple(lut.scalar_range) == (0.0, 10.0)
    assert "distance to" in scene.scalar_bar.GetTitle() and scene.scalar_bar.GetDrawBelowRangeSwatch()
    # The same in the jaw frame: contact is between the tongue and the palate.
    window.state.set_reference("jaw")
    np.testing.assert_allclose(scene.surface.point_data["value"], values, atol=1e-6)
    window.state.set_color("displacement")
    assert not scene.scalar_bar.GetDrawBelowRangeSwatch()
    assert np.allclose(scene.surface.point_data["value"], frames.scalars["displacement"][i])


def test_the_midline_plot_follows_the_cursor(qtbot, window, tmp_path):
    path = tmp_path / "roof.stl"
    flat_palate().save(path)
    session = simulate_with_palate(qtbot, window, path)
    panel, frames = window.palate_panel, session.frames
    window.tabs.setCurrentWidget(panel)
    qtbot.waitUntil(panel.isVisible)
    profile = panel.profile
    assert profile is not None and len(profile.position_mm) >= 5
    assert np.all(np.diff(profile.position_mm) > 0) and profile.position_mm[0] < 3  # from the tip backwards
    for t in (4.0, 5.3, 5.62):
        window.state.set_time(t)
        i = frames.frame_at(t)
        assert panel.shown_frame == i and panel.cursor_time == t
        head = frames.points[i] + session.motion.jaw_offset[i]
        expected = np.full(len(profile.bins), np.inf)
        np.minimum.at(expected, profile.bin_of, ROOF_MM - 1e3 * head[profile.nodes, 2])
        np.testing.assert_allclose(panel.midline.line.get_ydata(), expected, atol=1e-3)
        assert f"frame {i}/" in panel.midline.title.get_text()
    # Hidden, it does not redraw; shown again, it catches up with the cursor.
    window.tabs.setCurrentWidget(window.sensor_panel)
    window.state.set_time(6.0)
    assert panel.shown_frame == frames.frame_at(5.62)
    window.tabs.setCurrentWidget(panel)
    assert panel.shown_frame == frames.frame_at(6.0)
    # The contact timeline has the penetration over time, with the cursor.
    assert panel.timeline.ax.lines and panel.timeline.cursor_time == 6.0


def test_vtk_and_video_exports_in_the_head_and_the_jaw_frame(qtbot, window, tmp_path):
    import pyvista as pv

    from tonguevis.render.mp4 import probe_streams
    from tonguevis.render.video import export_video, export_vtk_series

    session = show_and_simulate(qtbot, window, demo_session(3.5, 5.6))
    motion = session.motion
    i = strongest_jaw_frame(session)
    offset = motion.jaw_offset[i]
    for frame, shift in (("head", offset), ("jaw", np.zeros(3))):
        folder = tmp_path / frame
        export_vtk_series(session, folder, frame=frame)
        grid = pv.read(folder / f"frame_{i:05d}.vtu")
        np.testing.assert_allclose(grid.points, motion.deformed_points(i) + shift, atol=1e-6)
        np.testing.assert_allclose(grid.point_data["deformation"], motion.displacement(i), atol=1e-6)
        np.testing.assert_allclose(grid.point_data["displacement"], motion.displacement(i) + shift, atol=1e-6)
        readme = (folder / "README.txt").read_text()
        assert readme.startswith(f"Frame of reference: {frame} frame")
        jaw = np.loadtxt(folder / "jaw_offset.csv", delimiter=",", skiprows=1)
        np.testing.assert_allclose(jaw[i, 1:], offset, atol=1e-9)
        out = tmp_path / f"{frame}.mp4"
        export_video(session, out, 5.3, 5.5, fps=10, size=(320, 240), frame=frame, mode="contact")
        assert "video" in probe_streams(out)
    with pytest.raises(ValueError, match="frame of reference"):
        export_vtk_series(session, tmp_path / "x", frame="mouth")


def test_motion_vtk_series_in_both_frames(qtbot, window, tmp_path):
    import meshio

    session = show_and_simulate(qtbot, window, demo_session(3.5, 5.6))
    motion = session.motion
    i = strongest_jaw_frame(session)
    head = meshio.read(motion.to_vtk_series(tmp_path / "head", frames=[i]).with_name(f"frame_{i:05d}.vtu"))
    jaw = meshio.read(motion.to_vtk_series(tmp_path / "jaw", frames=[i], frame="jaw").with_name(f"frame_{i:05d}.vtu"))
    np.testing.assert_allclose(head.points, motion.deformed_points(i) + motion.jaw_offset[i], atol=1e-12)
    np.testing.assert_allclose(jaw.points, motion.deformed_points(i), atol=1e-12)
    np.testing.assert_allclose(head.point_data["deformation"], jaw.point_data["deformation"], atol=1e-15)
    assert "head frame" in (tmp_path / "head" / "README.txt").read_text()
    assert "jaw frame" in (tmp_path / "jaw" / "README.txt").read_text()


def test_fit_palate_from_traces_in_the_worker(qtbot, window, tmp_path):
    """File ▸ Fit palate from traces: the real Opti-Speech traces, fitted off the GUI thread, saved and used."""
    from tests.conftest import shared_file
    from tonguevis.palate import PalateSurface

    traces = sorted(shared_file("ema", "optispeech").glob("00[234]_*.tsv"))
    assert len(traces) == 3
    out = tmp_path / "osn12"
    window.fit_palate(traces, out)
    qtbot.waitUntil(lambda: isinstance(window.palate, PalateSurface), timeout=120000)
    assert (tmp_path / "osn12.stl").exists() and (tmp_path / "osn12.palate.npz").exists()
    assert window.palate.metadata["rms_m"] < 1e-3 and window.palate.metadata["file"] == str(tmp_path / "osn12.stl")
    assert "palate" in window.palate_panel.header.text() or window.session is None


def test_view_with_a_bad_palate_file_is_one_line_naming_it(tmp_path, capsys):
    from tonguevis.cli import main

    bad = tmp_path / "palate.stl"
    bad.write_text("not a mesh\n")
    for argv in (["view", str(bad.with_name("none.tsv")), "--palate", str(bad), "--screenshot", str(tmp_path / "x.png")],
                 ["export-video", "--palate", str(bad), "--out", str(tmp_path / "x.mp4")]):
        code = main(argv)
        lines = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(lines) == 1, lines
        assert str(bad) in lines[0] and "Traceback" not in lines[0]
    assert not (tmp_path / "x.png").exists() and not (tmp_path / "x.mp4").exists()


@pytest.mark.slow
def test_view_and_export_video_against_the_generic_palate_in_either_frame(tmp_path):
    """The commands on the demo /ta/: --palate generic (contact on), the jaw frame, the contact colouring."""
    from tests.gui.test_midsagittal_and_cli import _default_model_available, _run
    from tests.gui.conftest import DEMO
    from tonguevis.render.mp4 import probe_streams

    if not (DEMO.exists() and _default_model_available()):
        pytest.skip("needs the demo corpus and the shipped mesh")
    out = tmp_path / "jaw.mp4"
    result = _run("export-video", str(DEMO), "--palate", "generic", "--reference", "jaw", "--color", "contact",
                  "--out", str(out), "--start", "5.5", "--end", "5.8", "--modes", "20", "--size", "320x240",
                  "--quiet", timeout=170)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "(jaw frame" in result.stdout and "video" in probe_streams(out)
    shot = tmp_path / "view.png"
    result = _run("view", str(DEMO), "--palate", "generic", "--reference", "jaw", "--color", "contact",
                  "--modes", "20", "--screenshot", str(shot), timeout=170)
    assert result.returncode == 0, result.stderr[-2000:]
    assert shot.stat().st_size > 50_000


def test_fitting_a_palate_to_a_recording_without_a_probe_is_a_dialog(qtbot, window, tmp_path):
    from tests.gui.conftest import DEMO

    if not DEMO.exists():
        pytest.skip(f"demo corpus not built: {DEMO}")
    window.fit_palate([DEMO], tmp_path / "palate.stl")
    qtbot.waitUntil(lambda: window.last_dialog is not None and window.last_dialog.isVisible(), timeout=60000)
    text = window.last_dialog.text()
    assert "no probe sensor 'PROBE'" in text and DEMO.name in text and "Palate fit" in window.last_dialog.windowTitle()
    assert window.palate is None and not (tmp_path / "palate.stl").exists()
    window.last_dialog.close()


def _patch_shapes(motion) -> int:
    """Three local shapes per sensor, and each humped sensor's hump (3 translations, 3 x HUMP_TILTS leans)."""
    from tonguevis.sim.patches import HUMP_TILTS, humped_sensors

    humped = humped_sensors(motion.sensor_names) if motion.metadata["sensor_patches"].get("hump_mm") else []
    return 3 * len(motion.sensor_nodes) + 3 * (1 + HUMP_TILTS) * len(humped)


def test_sensors_on_the_surface_from_the_simulation_menu(qtbot, window):
    """Sensors on the surface is the default (the menu item ticked, every measured sensor on its node);
    unticking Simulation ▸ Sensors on the surface simulates again with the modes alone, ticking it
    puts the patches back."""
    session = show_and_simulate(qtbot, window, demo_session())
    assert window.patches_action.isChecked() and window.sensor_patches == "default"
    assert session.motion.metadata["sensor_patches"]["shapes"] == _patch_shapes(session.motion)
    assert np.nanmax(session.motion.sensor_residual) < 1e-9
    with qtbot.waitSignal(window.simulation_finished, timeout=60000) as blocker:
        window.patches_action.trigger()
    assert blocker.args == [True] and window.sensor_patches is None
    assert "sensor_patches" not in window.session.motion.metadata
    assert np.nanmax(window.session.motion.sensor_residual) > 1e-4  # the modes alone leave a gap
    with qtbot.waitSignal(window.simulation_finished, timeout=60000):
        window.patches_action.trigger()
    motion = window.session.motion
    assert motion.metadata["sensor_patches"]["shapes"] == _patch_shapes(motion)
    assert np.nanmax(motion.sensor_residual) < 1e-9


def test_the_midline_plot_holds_every_frames_curve(qtbot, window, tmp_path):
    """Issue 37: the midline plot's range came from the rest frame (-2 mm to 12 mm on the real /ta/), and
    the curve left it below and above. Now no frame's distances fall outside it."""
    from tonguevis.render.drawing import head_points

    path = tmp_path / "roof.stl"
    flat_palate().save(path)
    session = simulate_with_palate(qtbot, window, path)
    panel, frames = window.palate_panel, session.frames
    window.tabs.setCurrentWidget(panel)
    qtbot.waitUntil(panel.isVisible)
    every = np.array([panel.profile.distances(session.shown_palate, head_points(frames, i))
                      for i in range(frames.n_frames)])
    low, high = panel.midline.ax.get_ylim()
    assert low <= np.nanmin(every) and np.nanmax(every) <= high, (low, high, np.nanmin(every), np.nanmax(every))
    assert high - low < 1.5 * (np.nanmax(every) - min(np.nanmin(every), 0.0)) + 4  # and not far wider
