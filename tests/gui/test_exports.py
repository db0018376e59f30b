"""Exports: whole-window PNG (3D painted in, not blank), MP4 with video and audio, VTK series."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import demo_session, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


def as_array(image):
    from PySide6.QtGui import QImage

    image = image.convertToFormat(QImage.Format.Format_RGB888)
    w, h, stride = image.width(), image.height(), image.bytesPerLine()
    return np.frombuffer(image.constBits(), dtype=np.uint8, count=h * stride).reshape(h, stride)[:, : 3 * w].reshape(h, w, 3)


def test_window_screenshot_is_not_blank_and_shows_the_3d_views(qtbot, window, tmp_path):
    from PySide6.QtCore import QPoint
    from PySide6.QtGui import QImage

    show_and_simulate(qtbot, window, demo_session())
    window.state.set_time(5.6)
    qtbot.wait(300)
    path = tmp_path / "window.png"
    window.export_screenshot(path)
    image = QImage(str(path))
    assert image.width() == window.width() and image.height() == window.height()
    pixels = as_array(image).astype(float)
    assert pixels.std() > 20
    # The 3D area: not one flat colour (background only) and not black (unread GL surface).
    interactor = window.view3d.plotter.interactor
    corner = interactor.mapTo(window, QPoint(0, 0))
    area = pixels[corner.y(): corner.y() + interactor.height(), corner.x(): corner.x() + interactor.width()]
    assert area.std() > 10 and area.mean() > 20
    # The tongue is drawn in the main view: its colour-mapped pixels differ from the background's.
    background = area[5:15, -200:-190].reshape(-1, 3).mean(axis=0)
    assert np.mean(np.linalg.norm(area - background, axis=2) > 60) > 0.02


def test_video_has_video_and_audio_streams(qtbot, window, tmp_path):
    from tonguevis.render.mp4 import probe_streams
    from tonguevis.render.video import export_video

    session = show_and_simulate(qtbot, window, demo_session())
    out = tmp_path / "clip.mp4"
    export_video(session, out, 5.3, 5.7, fps=20, size=(320, 240))
    assert out.stat().st_size > 1000
    assert sorted(probe_streams(out)) == ["audio", "video"]
    assert [p.name for p in tmp_path.iterdir()] == ["clip.mp4"]  # no temporary file left


def test_video_of_empty_range_is_an_error(qtbot, window, tmp_path):
    from tonguevis.render.video import ExportError, export_video

    session = show_and_simulate(qtbot, window, demo_session(3.5, 5.5))
    with pytest.raises(ExportError, match="empty time range"):
        export_video(session, tmp_path / "x.mp4", 5.0, 4.0)
    assert not (tmp_path / "x.mp4").exists()


def test_vtk_series_round_trip(qtbot, window, tmp_path):
    import pyvista as pv

    from tonguevis.render.video import export_vtk_series

    session = show_and_simulate(qtbot, window, demo_session(3.5, 5.6))
    frames = session.frames
    pvd = export_vtk_series(session, tmp_path / "series")
    files = sorted((tmp_path / "series").glob("frame_*.vtu"))
    assert len(files) == frames.n_frames
    assert pvd.read_text().count("<DataSet") == frames.n_frames
    i = frames.n_frames - 1
    grid = pv.read(files[i])
    # The head frame by default: the simulated tongue carried by the jaw's translation.
    motion = session.motion
    assert np.allclose(grid.points, motion.deformed_points(i) + motion.jaw_offset[i], atol=1e-6)
    whole = frames.whole_mesh()  # the view's frames compute the drawn surface only
    assert np.allclose(grid.point_data["energy_density"], whole.scalars["energy"][i])
