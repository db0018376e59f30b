"""The 3D views (main + top/front/lateral) as a Qt widget, linked to the AppState."""

from __future__ import annotations

import time

import numpy as np
from PySide6.QtCore import QElapsedTimer, Signal
from PySide6.QtWidgets import QLabel, QPushButton, QVBoxLayout, QWidget

from tonguevis.appstate import AppState, COLOR_MODES, REFERENCE_FRAMES, connected
from tonguevis.render.drawing import contact_line, draw_frame
from tonguevis.gui.elastic_label import ElasticComboBox, ElasticLabel
from tonguevis.gui.flow_layout import FlowLayout
from tonguevis.render.scene import TongueScene, frame_text, scene_setup, surface_faces

#: Each colouring as the app names it: the command line's name (``--color contact``) first, so that the
#: two say the same word, then what it shows where the name alone does not say it.
COLOUR_LABELS = {"displacement": "displacement magnitude", "energy": "energy: elastic energy density",
                 "contact": "contact: distance to palate", "plain": "plain",
                 "difference": "difference: distance to B (compared recording)"}
#: During playback the status line (frame of reference, palate contact) changes at most this
#: often (s of wall time): no one reads a line rewritten 30 times a second, and each costs
#: the palate distances of the frame.  A paused frame's line is always its own.
DESCRIBE_INTERVAL_S = 0.1
REFERENCE_LABELS = {"head": "head frame (jaw moving, palate fixed)", "jaw": "jaw frame (jaw's motion removed)"}


def image_views() -> bool:
    """Whether the 3D views render off screen and are painted as an image
    (:mod:`tonguevis.gui.image_views`) rather than in pyvistaqt's ``QOpenGLWidget``: on X11 and
    Windows, unless ``TONGUEVIS_VIEWS=qopenglwidget`` (``TONGUEVIS_VIEWS=image`` forces them);
    elsewhere (Wayland, macOS) VTK's off-screen window may not exist and the ``QOpenGLWidget`` stays."""
    import os

    from PySide6.QtGui import QGuiApplication

    choice = os.environ.get("TONGUEVIS_VIEWS", "").lower()
    if choice in ("image", "qopenglwidget"):
        return choice == "image"
    return QGuiApplication.platformName() in ("xcb", "windows")


#: How the compared recording B is drawn inside A's views (a translucent ghost).
GHOST_COLOUR = "#8ff0ff"
GHOST_OPACITY = 0.4


def make_plotter(parent, multi_samples: int | None = None, auto_update: float | bool = 5.0, **kwargs):
    """A Qt plotter (pyvista ``BasePlotter`` API, ``.interactor`` the widget) for every 3D view of the
    app: an :class:`~tonguevis.gui.image_views.ImageInteractor` where :func:`image_views` says so,
    pyvistaqt's ``QtInteractor`` elsewhere.  One ``QOpenGLWidget`` anywhere in the window (even in
    a hidden tab) makes Qt composite the whole window through OpenGL, so every 3D view of the app
    must come from here.  ``multi_samples`` None: pyvista's default; ``auto_update``: the
    ``QtInteractor``'s renders per second by timer (the image views render when asked or painted)."""
    if multi_samples is None:
        import pyvista

        multi_samples = pyvista.global_theme.multi_samples
    if image_views():
        from tonguevis.gui.image_views import ImageInteractor

        return ImageInteractor(parent, multi_samples=multi_samples, **kwargs)
    from pyvistaqt import QtInteractor

    return QtInteractor(parent, auto_update=auto_update, multi_samples=multi_samples, **kwargs)


class View3D(QWidget):
    """The four 3D views.  ``described(str)`` says, at each new frame, which frame of reference
    they show and the palate contact there (the window's status bar shows it)."""

    described = Signal(str)

    def __init__(self, state: AppState, parent=None):
        super().__init__(parent)
        self.state = state
        self.session = None
        self.frame = -1
        self.renders = 0
        # No multisampling: under software OpenGL (Xvfb, VMs) 8x MSAA costs most of each frame.
        self.plotter = make_plotter(self, shape="1|3", splitting_position=0.72, multi_samples=0, auto_update=False)
        self.scene = TongueScene(self.plotter)
        self.colour = ElasticComboBox(minimum_characters=14)
        for mode in COLOR_MODES:
            self.colour.addItem(COLOUR_LABELS[mode], mode)
        self.reference = ElasticComboBox(minimum_characters=14)
        for frame in REFERENCE_FRAMES:
            self.reference.addItem(REFERENCE_LABELS[frame], frame)
        self.reference.setToolTip("Head frame: the tongue and the jaw move with the jaw, the palate is fixed (as seen\n"
                                  "from outside). Jaw frame: the jaw's motion removed, as the tongue is simulated.")
        # The combos' long entries (e.g. "head frame (jaw moving, palate fixed)") show whole where
        # the window has room and are cut only in a narrow one: the views' bar does not set a
        # minimum window width wider than a laptop's screen.
        for combo in (self.colour, self.reference):
            combo.setToolTip(combo.toolTip() or "the 3D views' colouring")
        self.reset = QPushButton("Reset camera")
        # The model's description (nodes, modes, sensors, palate) is as long as the names in
        # it: cut at the window's edge rather than widening the window past the screen.
        self.message = ElasticLabel("", minimum_width=120)
        # The controls wrap onto a second line in a narrow window (1280 pixels, a recording compared
        # beside): the combos keep their whole entries; the model's description has a line of its own.
        bar = FlowLayout()
        bar.addWidget(QLabel("Colour by"))
        bar.addWidget(self.colour)
        bar.addWidget(self.reference)
        bar.addWidget(self.reset)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(2)
        layout.addLayout(bar)
        layout.addWidget(self.message)
        layout.addWidget(self.plotter.interactor, 1)
        self.colour.currentIndexChanged.connect(lambda _i: state.set_color(self.colour.currentData(), self))
        self.reference.setCurrentIndex(REFERENCE_FRAMES.index(state.reference))
        self.reference.currentIndexChanged.connect(
            lambda _i: state.set_reference(self.reference.currentData(), self))
        self.reset.clicked.connect(self.reset_camera)
        self.cursor_time = state.time
        #: The recording time (s) of the picture on screen: during playback each frame is drawn
        #: for the time it will be shown at, a frame interval ahead (see :meth:`show_time`).
        self.shown_time = state.time
        self._frame_clock = QElapsedTimer()
        self._frame_interval = 0.0  # wall seconds between playback's frames (running mean)
        self._latency = 0.0  # wall seconds from a frame's clock reading to its paint (running mean)
        self._time_read = None  # time.perf_counter() when the last frame's time came
        self._described_at = -np.inf  # time.perf_counter() of the last status line made in playback
        interactor = self.plotter.interactor
        self._pipelined_views = hasattr(interactor, "set_pipelined")
        if self._pipelined_views:
            interactor.on_shown = self._on_shown
            interactor.on_painted = self._on_painted
        self.drawn = None  # the FrameDrawing shown (tests read it)
        self.ghosts: list = []  # the compared recording's tongue in each of the four views (the ghost layout)
        connected(state.events.time, self._on_time)
        connected(state.events.comparison, self._on_comparison)
        connected(state.events.compare_view, self._on_comparison)
        connected(state.events.playing, self._on_playing)
        connected(state.events.color, self._on_colour)
        connected(state.events.reference, self._on_reference)

    def set_session(self, session) -> None:
        self.session = session
        self.frame = -1
        frames = getattr(session, "frames", None)
        if frames is None:
            self.message.setText("simulating…" if session is not None else "")
            return
        model = frames.motion.model
        self.scene.build(frames.points[0], surface_faces(model), **scene_setup(session))
        self.scene.set_mode(self.state.color)
        palate = getattr(session, "shown_palate", None)
        from tonguevis.sim.patches import modes_text

        self.message.setText(f"{model.mesh.n_nodes} nodes, {modes_text(frames.motion, long=False)}, "
                             f"sensors {', '.join(frames.motion.sensor_names)}"
                             + (f"; {palate.label}" if palate is not None else ""))
        self._show_comparison()  # the scene was built anew: its colour range and ghosts too
        self.show_time(self.state.time)

    # -- a compared recording (the app model's comparison) -------------------
    def _on_comparison(self, _event) -> None:
        self._show_comparison()
        self.frame = -1
        self.show_time(self.state.time)

    def _show_comparison(self) -> None:
        """The app model's comparison in these views: the colouring "distance to B" offered while one of the same
        mesh is shown (dropped, back to displacement, when none is), and B's ghost in the ghost layout."""
        shown = self.state.comparison
        if shown is not None and shown.clim is not None:
            self.scene.set_colour_range("difference", shown.clim, "distance to\nB (mm)")
        elif self.state.color == "difference":
            self.state.set_color("displacement", self)
        self._remove_ghosts()
        if shown is not None and self.state.compare_view.layout == "ghost" and self.scene.surface is not None:
            self._add_ghosts(shown.surface_b)

    def _add_ghosts(self, surface) -> None:
        from tonguevis.render.surface_geometry import hidden_side

        plotter = self.plotter
        # The ghost is B's closed tongue seen from outside: drawn without its far side, one translucent layer
        # everywhere (its two walls, blended in triangle order, showed the triangles as patches).
        faces = np.asarray(surface.faces).reshape(-1, 4)[:, 1:]
        hidden = hidden_side(np.asarray(surface.points), faces)
        for index in range(len(plotter.renderers)):
            plotter.subplot(*_subplot_index(plotter, index))
            actor = plotter.add_mesh(surface, color=GHOST_COLOUR, opacity=GHOST_OPACITY, name=f"ghost_b{index}",
                                     reset_camera=False, show_scalar_bar=False, scalars=None)
            actor.mapper.scalar_visibility = False
            actor.prop.interpolation = "gouraud"
            actor.prop.SetBackfaceCulling(hidden == "back")
            actor.prop.SetFrontfaceCulling(hidden == "front")
            self.ghosts.append(actor)
        plotter.subplot(*_subplot_index(plotter, 0))

    def _remove_ghosts(self) -> None:
        for index, actor in enumerate(self.ghosts):
            try:
                self.plotter.renderers[index].RemoveActor(actor)
            except Exception:  # the scene was rebuilt meanwhile
                pass
        self.ghosts = []

    def _on_time(self, event) -> None:
        self.show_time(event.value)

    def _on_playing(self, event) -> None:
        """Playback pipelines the views' frames (each read back a frame after its render, so
        no paint waits for the rasteriser); when it stops, the exact time is drawn at once."""
        if not self._pipelined_views:
            return
        self.plotter.interactor.set_pipelined(event.value)
        self._frame_interval = self._latency = 0.0
        self._time_read = None
        self._described_at = -np.inf
        self._frame_clock.start()
        if not event.value:
            self.frame = -1  # drawn for a time ahead: draw the time playback stopped at
            self.show_time(self.state.time)

    def _lead(self) -> float:
        """Recording seconds from the clock's time now to the paint of the frame drawn now: one
        interval between playback's frames (the frame is painted at the next one), plus the time
        from a frame's clock reading to its paint (running means of the last few; at most 0.1 s
        and 0.05 s of wall time)."""
        self._time_read = time.perf_counter()
        dt = min(self._frame_clock.restart() * 1e-3, 0.1)
        self._frame_interval = dt if self._frame_interval == 0.0 else 0.7 * self._frame_interval + 0.3 * dt
        return (self._frame_interval + self._latency) * self.state.speed

    def _on_painted(self) -> None:
        if self._time_read is None or not self.state.playing:
            return
        latency = min(time.perf_counter() - self._time_read, 0.05)
        self._latency = latency if self._latency == 0.0 else 0.7 * self._latency + 0.3 * latency
        self._time_read = None

    def _on_shown(self, tag) -> None:
        if tag is None:
            return
        self.shown_time, line = tag
        if line is not None:
            self.described.emit(line)

    def show_time(self, t: float) -> None:
        self.cursor_time = t
        frames = getattr(self.session, "frames", None)
        if frames is None:
            return
        pipelined = self._pipelined_views and self.state.playing
        if pipelined:
            t = min(t + self._lead(), self.state.playback_bounds()[1])
        i = frames.frame_at(t)
        if i == self.frame:
            if pipelined:
                self.plotter.interactor.show_rendered()  # e.g. slow playback: the last frame is due
            return
        self.frame = i
        reference = self.state.reference
        drawn = draw_frame(self.session, i, reference, self.state.color)
        shown = self.state.comparison
        if self.state.color == "difference" and shown is not None and shown.clim is not None:
            drawn.scalars = shown.difference(i)  # A coloured by the distance to B at the matched moment
        self.drawn = drawn
        self.scene.update(drawn.points, drawn.scalars, drawn.sensor_points, drawn.targets,
                          frame_text(frames, i, self.session.productions, drawn.caption), render=False,
                          context_offsets=drawn.context_offsets, context_shapes=drawn.context_shapes)
        self.scene.set_view_labels(f" · {drawn.caption.split(':')[0]}")
        line = None
        if not pipelined:
            self.described.emit(contact_line(self.session, i, reference))
        elif time.perf_counter() - self._described_at >= DESCRIBE_INTERVAL_S:
            self._described_at = time.perf_counter()
            line = contact_line(self.session, i, reference)
        self.state.frame_drawn(i, self)  # views drawn in step with this one (the compare panel)
        # One render per frame: the image view renders now and paints later (the frame
        # rasterises meanwhile; pipelined, its description is told when it is shown);
        # pyvistaqt's paintGL always renders, so there a repaint is asked.
        request = getattr(self.plotter.interactor, "request_render", None)
        if request is not None:
            request(tag=(t, line))
        else:
            self.shown_time = t
            self.plotter.interactor.update()
        self.renders += 1

    def _on_colour(self, event) -> None:
        index = self.colour.findData(event.value)
        if index != self.colour.currentIndex():
            self.colour.setCurrentIndex(index)
        self.scene.set_mode(event.value)
        self.frame = -1
        self.show_time(self.state.time)

    def _on_reference(self, event) -> None:
        index = self.reference.findData(event.value)
        if index != self.reference.currentIndex():
            self.reference.blockSignals(True)
            self.reference.setCurrentIndex(index)
            self.reference.blockSignals(False)
        self.frame = -1
        self.show_time(self.state.time)

    def set_context_visible(self, visible: bool) -> None:
        self.scene.set_context_visible(visible)
        self.plotter.interactor.update()

    def reset_camera(self) -> None:
        self.scene.reset_cameras()
        self.plotter.render()

    def close_view(self) -> None:
        self.plotter.close()


def _subplot_index(plotter, index: int) -> tuple[int, ...]:
    """The ``subplot`` arguments of renderer ``index`` of ``plotter``."""
    loc = plotter.renderers.index_to_loc(index)
    return tuple(int(v) for v in np.atleast_1d(loc))
