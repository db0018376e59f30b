"""What keeps playback fast: frames dropped (never delayed) behind the clock, the 3D views
painted in software from VTK's off-screen frame (no OpenGL composition of the window), one
render per frame, and no full matplotlib redraw while playing."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import demo_session, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


class StepClock:
    """A clock the test moves by hand (recording seconds)."""

    kind = "wall"

    def __init__(self):
        self.now = 0.0

    def start(self, t0, t1, speed):
        self.now = t0

    def time(self):
        return self.now

    def exhausted(self):
        return False

    def stop(self):
        pass


def test_slow_frames_are_dropped_not_delayed(qtbot, monkeypatch):
    """Each tick shows the clock's time, however long the last frame took to draw: a draw
    that takes 0.25 s of a 100 frames/s recording skips 25 frames instead of falling behind."""
    from PySide6.QtCore import QObject

    import tonguevis.gui.playback as playback
    from tonguevis.appstate import AppState

    parent = QObject()
    state = AppState(0.0, 10.0, 0.01)
    controller = playback.PlaybackController(state, parent)
    clock = StepClock()
    monkeypatch.setattr(controller, "_make_clock", lambda: (clock, "test clock"))
    shown = []

    state.events.time.connect(lambda event: shown.append(event.value))
    state.set_time(1.0)
    state.set_playing(True)
    controller.timer.stop()  # ticks by hand
    shown.clear()
    for _ in range(4):
        clock.now += 0.25  # the last frame took a quarter of a second to draw
        controller.tick()
    state.set_playing(False)
    # Every tick shows where the clock is now, not the frame after the last one shown.
    assert np.allclose(shown, [1.25, 1.5, 1.75, 2.0])
    assert np.allclose(np.diff(shown), 0.25)  # 25 frames skipped each time
    controller.shutdown()


def test_playback_keeps_up_with_the_wall_clock_on_a_slow_view(qtbot, monkeypatch):
    """With a real wall clock and a view that needs 40 ms a frame (slower than the 15 ms tick),
    the time shown trails the clock by at most one draw, and frames are skipped."""
    from PySide6.QtCore import QObject

    import tonguevis.gui.playback as playback
    from tonguevis.appstate import AppState

    parent = QObject()
    state = AppState(0.0, 10.0, 0.01)
    controller = playback.PlaybackController(state, parent)
    shown = []

    def slow_view(event):
        shown.append((event.value, controller.clock.time() if controller.clock else None))
        time.sleep(0.04)

    state.events.time.connect(slow_view)
    state.set_time(1.0)
    state.set_playing(True)
    qtbot.waitUntil(lambda: state.time > 1.6, timeout=5000)
    state.set_playing(False)
    lag = [clock - shown_t for shown_t, clock in shown if clock is not None]
    assert max(lag) < 0.005  # shown at the clock's time when it was read, not queued behind
    distinct = sorted({round(t, 2) for t, _ in shown})
    frames_passed = round(100 * (distinct[-1] - distinct[0]))
    assert len(distinct) < 0.6 * frames_passed  # ~40 ms a frame at 100 frames/s: most frames skipped
    controller.shutdown()


def test_three_d_views_are_painted_in_software_one_render_per_frame(qtbot, window):
    """On X11 the window holds no QOpenGLWidget (one would make Qt composite the whole window
    through OpenGL), the 3D views are an image a plain grab sees, and playback renders the four
    views once per frame shown, with no full redraw of any matplotlib canvas."""
    from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
    from PySide6.QtGui import QGuiApplication
    from PySide6.QtOpenGLWidgets import QOpenGLWidget

    from tonguevis.gui.image_views import ImageInteractor
    from tonguevis.render.scene import BACKGROUND
    from tonguevis.gui.view3d import image_views

    if QGuiApplication.platformName() != "xcb" or not image_views():
        pytest.skip("image views are used on X11 only")
    show_and_simulate(qtbot, window, demo_session())
    plotter = window.view3d.plotter
    assert isinstance(plotter, ImageInteractor)
    assert window.findChildren(QOpenGLWidget) == []

    # A plain QWidget.grab (no VTK read-back pasted in) shows the views: background and tongue.
    state = window.state
    state.set_time(5.6)
    qtbot.wait(200)
    image = plotter.grab().toImage()
    rgb = np.array([[image.pixelColor(x, y).getRgbF()[:3] for x in range(0, image.width(), 8)]
                    for y in range(0, image.height(), 8)])
    import matplotlib.colors as mcolors

    backdrop = np.linalg.norm(rgb - np.array(mcolors.to_rgb(BACKGROUND)), axis=-1) < 0.03
    assert 0.2 < backdrop.mean() < 0.95, backdrop.mean()

    state.set_time(5.2)
    qtbot.wait(300)  # the plots' first draws (after the simulation) are done
    draws = []
    for canvas in window.findChildren(FigureCanvasQTAgg):
        canvas.mpl_connect("draw_event", lambda _e, c=canvas: draws.append((type(c).__name__, round(state.time, 2))))
    renders, frames = plotter.renders, window.view3d.renders
    state.set_playing(True)
    qtbot.waitUntil(lambda: state.time > 6.0, timeout=10000)
    state.set_playing(False)
    qtbot.wait(100)
    new_frames = window.view3d.renders - frames
    assert new_frames > 3
    assert plotter.renders - renders <= new_frames + 1  # one render per frame (a paint may add one)
    assert draws == [], draws  # cursors move on an overlay: no canvas is redrawn while playing


def _pixels(image) -> np.ndarray:
    """(h, w, 3) RGB of a QImage."""
    from PySide6.QtGui import QImage

    image = image.convertToFormat(QImage.Format.Format_RGB888)
    rows = np.frombuffer(image.constBits(), dtype=np.uint8).reshape(image.height(), image.bytesPerLine())
    return rows[:, : 3 * image.width()].reshape(image.height(), image.width(), 3).copy()


def _sphere_view(qtbot):
    """An image view (320 x 240) of a white sphere on black, shown; returns (plotter, move) where
    move(dx) puts the sphere dx to the right of the centre."""
    import pyvista as pv
    from PySide6.QtGui import QGuiApplication

    from tonguevis.gui.image_views import ImageInteractor

    if QGuiApplication.platformName() != "xcb":
        pytest.skip("image views are used on X11 only")
    plotter = ImageInteractor(None)
    qtbot.addWidget(plotter)
    plotter.setFixedSize(320, 240)
    sphere = pv.Sphere(radius=0.5)
    rest = np.array(sphere.points)
    plotter.add_mesh(sphere, color="white")
    plotter.set_background("black")
    plotter.show()
    qtbot.waitExposed(plotter)
    qtbot.wait(200)

    def move(dx: float) -> None:
        sphere.points[:] = rest + [dx, 0.0, 0.0]

    return plotter, move


def test_a_new_frame_renders_at_once_and_the_paint_shows_the_latest(qtbot):
    """A frame change renders the views at once (Mesa rasterises it while the GUI thread goes on
    with the plots), and the paint shows that render without rendering again; a second change
    before the paint makes the paint render the newer frame, never show the stale one."""
    plotter, move = _sphere_view(qtbot)

    renders, paints = plotter.renders, plotter.paints
    move(0.3)
    plotter.request_render()
    assert plotter.renders == renders + 1  # rendered before any paint
    qtbot.waitUntil(lambda: plotter.paints > paints, timeout=5000)
    assert plotter.renders == renders + 1  # the paint showed that render
    shown_right = _pixels(plotter._image)

    renders, paints = plotter.renders, plotter.paints
    move(-0.1)
    plotter.request_render()  # rendered, not painted yet...
    move(-0.3)
    plotter.request_render()  # ...and already stale
    qtbot.waitUntil(lambda: plotter.paints > paints, timeout=5000)
    assert plotter.renders == renders + 2
    shown = _pixels(plotter._image)
    expected = np.asarray(plotter.screenshot(return_img=True))[..., :3]
    assert shown.shape == expected.shape
    assert np.abs(shown.astype(int) - expected).mean() < 0.5  # the sphere moved left
    assert np.abs(shown.astype(int) - shown_right).mean() > 5  # not where it was
    plotter.close()


def test_pipelined_frames_are_painted_one_request_later_and_never_wait(qtbot):
    """Pipelined (playback), each request renders its frame and reads back the one before it,
    which the paint then shows without rendering: the paint never waits for the rasteriser.
    The tags say which frame is on screen; a camera move still paints at once, and ending the
    pipeline paints the last frame asked for."""
    plotter, move = _sphere_view(qtbot)
    told = []
    plotter.on_shown = told.append

    def picture(dx: float) -> np.ndarray:
        move(dx)
        return np.asarray(plotter.screenshot(return_img=True))[..., :3].astype(int)

    left, right = picture(-0.3), picture(0.3)
    move(0.0)
    plotter.request_render(tag="centre")
    qtbot.waitUntil(lambda: plotter.shown_tag == "centre", timeout=5000)

    plotter.set_pipelined(True)
    renders, paints = plotter.renders, plotter.paints
    move(-0.3)
    plotter.request_render(tag="left")
    assert plotter.renders == renders + 1  # rendered at once...
    qtbot.wait(100)
    assert plotter.shown_tag == "centre"  # ...and not read back: the screen keeps the last frame
    move(0.3)
    plotter.request_render(tag="right")
    assert plotter.shown_tag == "left" and told[-1] == "left"  # the frame before is read back now
    paints = plotter.paints
    qtbot.waitUntil(lambda: plotter.paints > paints, timeout=5000)
    assert plotter.renders == renders + 2  # the paint rendered nothing
    shown = _pixels(plotter._image)
    assert np.abs(shown - left).mean() < 0.5 < np.abs(shown - right).mean()

    plotter.set_pipelined(False)  # playback stops: the last frame asked for is painted
    qtbot.waitUntil(lambda: plotter.shown_tag == "right", timeout=5000)
    assert np.abs(_pixels(plotter._image) - right).mean() < 0.5
    assert told == ["centre", "left", "right"]

    # A repaint asked for while pipelined (the widget's Render(), as after a camera change) paints
    # the scene as it is now, at once, not the frame rendered before the change.
    plotter.set_pipelined(True)
    move(-0.3)
    plotter.request_render(tag="left again")
    plotter.camera.zoom(2.0)
    renders = plotter.renders
    plotter.Render()
    qtbot.waitUntil(lambda: plotter.renders > renders, timeout=5000)
    qtbot.waitUntil(lambda: plotter.shown_tag == "left again", timeout=5000)
    zoomed = np.asarray(plotter.screenshot(return_img=True))[..., :3].astype(int)
    assert np.abs(_pixels(plotter._image) - zoomed).mean() < 0.5
    plotter.close()


def test_playback_draws_each_frame_for_the_time_it_is_shown_and_the_status_line_at_ten_hertz(qtbot, window):
    """While playing, the 3D views draw each frame for the time it will be painted at (ahead
    of the clock by about a frame, since it is painted a frame later), and the status line is
    made at most ten times a second; once stopped, the picture and the status line are those of
    the time playback stopped at, exactly."""
    from tonguevis.render.drawing import contact_line
    from tonguevis.gui.view3d import DESCRIBE_INTERVAL_S

    session = show_and_simulate(qtbot, window, demo_session())
    state, view3d = window.state, window.view3d
    state.set_time(5.2)
    qtbot.wait(200)
    plotter = view3d.plotter
    if not hasattr(plotter, "set_pipelined"):
        pytest.skip("the views are pipelined when they are image views (X11)")
    requests, lines = [], []
    original = plotter.request_render

    def recorded(tag=None):
        requests.append((tag[0], state.time))
        original(tag=tag)

    plotter.request_render = recorded
    view3d.described.connect(lines.append)
    started = time.perf_counter()
    state.set_playing(True)
    qtbot.waitUntil(lambda: state.time > 6.5, timeout=15000)
    elapsed = time.perf_counter() - started
    playing_lines = len(lines)
    state.set_playing(False)
    plotter.request_render = original
    qtbot.wait(200)

    leads = np.array([drawn - clock for drawn, clock in requests[:-1]])  # the last: after the stop
    assert len(leads) > 5
    assert (leads >= 0).all() and 0.005 < np.median(leads) < 0.15, leads
    assert requests[-1][0] == requests[-1][1] == state.time  # the stop time, not ahead
    assert 2 <= playing_lines <= elapsed / DESCRIBE_INTERVAL_S + 2, (playing_lines, elapsed)
    assert len(requests) > 1.5 * playing_lines  # frames drawn more often than the line is made
    i = session.frames.frame_at(state.time)
    assert window.frame_status.text() == contact_line(session, i, state.reference)
    assert view3d.shown_time == state.time
    assert np.allclose(view3d.scene.surface.points, session.frames.points[i] + session.motion.jaw_offset[i])
