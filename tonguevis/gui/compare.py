"""Two recordings compared in the app: the second one (B) beside the first (A) or inside its views.

The second recording is a session in the app model's ``"compare"`` slot
(:meth:`AppState.set_session`), simulated like the first.  The comparison
itself is Qt-free (:class:`tonguevis.analysis.compare.Comparison`): which
moment of B goes with each moment of A (productions lined up by normalised
time, or absolute time) and how far apart the two tongues are.  Here it is
only shown:

- *side by side*: :class:`ComparePanel` draws B's tongue in its own view beside
  A's views, with A's main camera (one camera object: turning either view turns
  both);
- *ghost*: B's surface drawn translucent inside each of A's four views;
- *difference*: with the colouring "distance to B", A's surface (and B's) is
  coloured by the per-node distance between the two shapes at matched time, in
  the model frame (both recordings aligned onto the same tongue).

One transport drives both: the panel follows the app model's time and shows B
at the matched moment.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QComboBox, QLabel, QPushButton, QVBoxLayout, QWidget

from tonguevis.gui.elastic_label import ElasticLabel
from tonguevis.gui.flow_layout import FlowLayout
from tonguevis.errors import TonguevisError
from tonguevis.sim.motion import frame_label
from tonguevis.appstate import COMPARE_LAYOUTS, COMPARE_TIME_MODES, connected


#: How B is shown (the app model's :data:`~tonguevis.appstate.COMPARE_LAYOUTS`): beside A (its own view, A's
#: camera) or as a translucent ghost in A's views.
LAYOUTS = dict(zip(COMPARE_LAYOUTS, ("side by side", "ghost in A's views")))
#: How B's time follows A's (:class:`~tonguevis.analysis.compare.Comparison` modes).
TIME_MODES = dict(zip(COMPARE_TIME_MODES, ("per production", "absolute time")))
GHOST_PANEL_WIDTH = 460  # px: the panel's controls, when B is drawn inside A's views
#: Colour range of the distance between the tongues: at least this (mm), else the 98th percentile
#: of a sample of matched frames.
DIFFERENCE_MIN_RANGE_MM = 1.0
DIFFERENCE_SAMPLE_FRAMES = 200


def spans(productions) -> list:
    """Productions as objects with ``start``/``end`` (from (start, end) pairs or such objects)."""
    out = []
    for p in productions or []:
        if hasattr(p, "start"):
            out.append(p)
        else:
            out.append(SimpleNamespace(start=float(p[0]), end=float(p[1])))
    return out


def make_comparison(session_a, session_b, mode: str):
    """The :class:`Comparison` of two simulated sessions (production mode falls back to absolute
    time, with the reason, when a recording has no productions).  Returns (comparison, note)."""
    from tonguevis.analysis.compare import Comparison

    if mode == "production":
        try:
            return Comparison(session_a.motion, session_b.motion, "production", spans(session_a.productions),
                              spans(session_b.productions)), ""
        except TonguevisError as exc:
            return Comparison(session_a.motion, session_b.motion, "absolute"), f"{exc}: on absolute time"
    return Comparison(session_a.motion, session_b.motion, mode), ""


def frame_difference_mm(frames_a, i: int, frames_b, j: int) -> np.ndarray:
    """(n,) float32 distance (mm) between node k of A's frame ``i`` and of B's frame ``j``, in the model
    frame, from the drawing data (the nodes not drawn sit at rest in both: 0)."""
    return 1e3 * np.linalg.norm(frames_a.points[i] - frames_b.points[j], axis=1)


def difference_range(comparison, frames_a, frames_b) -> tuple[float, float]:
    """(0, high) mm: the 98th percentile of the distance over a sample of matched frames."""
    n = frames_a.n_frames
    picks = np.unique(np.linspace(0, n - 1, min(n, DIFFERENCE_SAMPLE_FRAMES)).astype(int))
    values = [frame_difference_mm(frames_a, int(i), frames_b, comparison.frame_b(frames_a.times[int(i)]))
              for i in picks]
    high = float(np.percentile(np.concatenate(values), 98)) if values else 0.0
    return 0.0, max(DIFFERENCE_MIN_RANGE_MM, high)


class ShownComparison:
    """What the app shows of a comparison, held by the app model (``state.comparison``) for every view:
    ``comparison`` (:class:`~tonguevis.analysis.compare.Comparison`), the two sessions, B's drawn surface
    ``surface_b`` (a PolyData the compare panel moves to B's matched frame; A's views draw it as a ghost), and
    ``clim`` (the colour range of the distance to B, mm; None when the meshes differ: no per-node distance)."""

    def __init__(self, comparison, session_a, session_b, surface_b, clim):
        self.comparison, self.session_a, self.session_b = comparison, session_a, session_b
        self.surface_b, self.clim = surface_b, clim
        self._last = None  # (i, j, distances): the pair last asked, once for A's colouring and B's

    def frame_b(self, i: int) -> int:
        """B's frame matched with A's frame ``i``."""
        return self.comparison.frame_b(float(self.session_a.frames.times[i]))

    def difference(self, i: int) -> np.ndarray:
        """(n,) mm :func:`frame_difference_mm` of A's frame ``i`` and B's matched frame."""
        j = self.frame_b(i)
        if self._last is None or self._last[:2] != (i, j):
            self._last = (i, j, frame_difference_mm(self.session_a.frames, i, self.session_b.frames, j))
        return self._last[2]


class ComparePanel(QWidget):
    """The second recording's controls and its view (side by side), following the app model.

    ``view_a``: A's :class:`~tonguevis.gui.view3d.View3D` (its main camera is shared, its
    views get the ghost and the difference colouring).
    """

    def __init__(self, state, view_a, parent=None):
        super().__init__(parent)
        from tonguevis.gui.view3d import make_plotter

        self.state, self.view_a = state, view_a
        self.comparison = None
        self.shown: ShownComparison | None = None
        self.note = ""
        self.frame_b = -1
        self.renders = 0
        self._surface = None  # B's drawn surface (PolyData), shared by the panel's view and the ghosts
        self._b_nodes = np.zeros(0, dtype=np.int64)  # B's surface nodes (the ones lit)
        self._b_values = None
        self._b_shaded = None
        self._clim: tuple[float, float] | None = None
        self._camera_seen = None
        self._observed_camera = None  # the vtkCamera whose moves repaint both views
        self._camera_observer = None
        self.title = ElasticLabel("", minimum_width=120)  # file names: elided, whole in the tooltip
        self.layout_box = QComboBox()
        for key, text in LAYOUTS.items():
            self.layout_box.addItem(text, key)
        self.time_box = QComboBox()
        for key, text in TIME_MODES.items():
            self.time_box.addItem(text, key)
        self.time_box.setToolTip("Per production: each production of B is laid over the same production of A by\n"
                                 "normalised time, so syllables line up whatever the speakers' rates.")
        self.close_button = QPushButton("Stop comparing")
        self.caption = QLabel("")
        self.caption.setWordWrap(True)
        # The title on a line of its own, the controls under it, wrapping where the pane is narrow.
        bar = FlowLayout()
        bar.addWidget(self.layout_box)
        bar.addWidget(self.time_box)
        bar.addWidget(self.close_button)
        self.plotter = make_plotter(self, multi_samples=0)
        self.plotter.set_background(_background())
        self.plotter.renderer.AddObserver("StartEvent", lambda *_a: self._shade_b())
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.title)
        layout.addLayout(bar)
        layout.addWidget(self.caption)
        layout.addWidget(self.plotter.interactor, 1)
        layout.addStretch(0)  # takes the room when the view is hidden (ghost): the controls stay on top
        self.layout_box.currentIndexChanged.connect(lambda _i: self.set_layout(self.layout_box.currentData()))
        self.time_box.currentIndexChanged.connect(lambda _i: self.set_time_mode(self.time_box.currentData()))
        connected(state.events.compare_view, self._on_compare_view)
        self.close_button.clicked.connect(lambda: state.set_session(None, "compare", self))
        # B follows the frame A draws (the model's frame_drawn event, sent as A draws each frame, also
        # for a new frame of reference or colouring): during playback A draws each frame ahead of the
        # clock for the moment it is painted, and B (its ghost in A's views, or its own view,
        # pipelined as A's) is drawn for the same moment.
        connected(state.events.frame_drawn, self._on_frame_drawn)
        connected(state.events.playing, self._on_playing)
        connected(state.events.session, self._on_sessions)
        connected(state.events.motion, self._on_sessions)
        self.setVisible(False)

    # -- what is compared --------------------------------------------------------------------
    @property
    def session_a(self):
        return self.state.session_of("primary")

    @property
    def session_b(self):
        return self.state.session_of("compare")

    @property
    def layout_mode(self) -> str:
        return self.state.compare_view.layout

    @property
    def time_mode(self) -> str:
        return self.state.compare_view.time_mode

    @property
    def difference_shown(self) -> bool:
        """Whether A's views offer the colouring "distance to B" (a comparison of one mesh is shown)."""
        return self._clim is not None and self.comparison is not None

    def _on_sessions(self, _event) -> None:
        self.rebuild()

    def rebuild(self) -> None:
        """Compare the app model's two sessions afresh (or hide, with no second one)."""
        a, b = self.session_a, self.session_b
        self.setVisible(b is not None)
        self.comparison, self.note, self.frame_b = None, "", -1
        self._clim = None
        if b is None:
            self.state.set_comparison(None, self)
            return
        self.title.setText(f"<b>B</b>: {b.name}  (A: {a.name if a is not None else '—'})")
        if a is None or a.frames is None or b.frames is None:
            self.caption.setText("simulating…")
            self.state.set_comparison(None, self)
            return
        self.comparison, self.note = make_comparison(a, b, self.time_mode)
        self._build_surface(b)
        self._clim = (difference_range(self.comparison, a.frames, b.frames) if self.comparison.same_mesh else None)
        self._share_camera()
        self._apply_layout()
        self.shown = ShownComparison(self.comparison, a, b, self._surface, self._clim)
        self.show_time(self.state.time)
        self.state.set_comparison(self.shown, self)  # A's views: the difference colouring, the ghost

    def _build_surface(self, session) -> None:
        """B's tongue, drawn as A's: lit at its vertices for the shared camera
        (:mod:`tonguevis.render.shading`, A's lights and material) and coloured as A is coloured."""
        import pyvista as pv

        from tonguevis.render.scene import SENSOR_COLOUR, add_lit_surface, faces_to_vtk
        from tonguevis.render.surface_geometry import VertexNormals, hidden_side
        from tonguevis.render.scene import surface_faces

        frames = session.frames
        faces = surface_faces(frames.motion.model)
        points = np.asarray(frames.points[0], dtype=np.float32)
        self.plotter.clear()
        hidden = hidden_side(points, faces)
        # Shading normals point out of the tongue whichever way its triangles are wound (as A's).
        self._normals = VertexNormals(np.asarray(faces)[:, ::-1] if hidden == "front" else faces, len(points))
        self._surface = pv.PolyData(points.copy(), faces_to_vtk(faces))
        self._surface.point_data["Normals"] = self._normals(points)
        self._surface.point_data.active_normals_name = "Normals"
        self._surface.point_data["rgb"] = np.zeros((len(points), 3), dtype=np.uint8)
        self._b_nodes = np.unique(np.asarray(faces, dtype=np.int64))
        self._b_values = None  # B's colouring values at this frame (None: the plain tongue colour)
        self._b_shaded = None  # what B's colours were last lit from
        self._b_actor = add_lit_surface(self.plotter, self._surface, "tongue_b", cull=hidden)
        n_sensors = max(len(frames.motion.sensor_names), 1)
        self._sensors = pv.PolyData(np.zeros((n_sensors, 3), dtype=np.float32))
        self.plotter.add_mesh(self._sensors, color=SENSOR_COLOUR, point_size=12, render_points_as_spheres=True,
                              name="sensors_b", reset_camera=False)
        self.plotter.add_text("B", position="upper_right", font_size=12, name="label_b")

    def b_colours(self) -> np.ndarray:
        """(m, 3) B's unlit colours in [0, 1] at its surface nodes: its values of A's colouring through
        A's lookup table (same colour, same value), or the plain tongue colour."""
        import pyvista as pv

        from tonguevis.render.scene import TONGUE_COLOUR, mapped_colours

        lut = self.view_a.scene.lookup_table
        if lut is None or self._b_values is None:
            return np.broadcast_to(np.asarray(pv.Color(TONGUE_COLOUR).float_rgb), (len(self._b_nodes), 3))
        return mapped_colours(lut, self._b_values[self._b_nodes])

    def _shade_b(self) -> None:
        """Light B's tongue for the shared camera when its frame, colouring or the camera changed
        (called as the panel's view starts rendering)."""
        if self._surface is None or self.layout_mode != "side":
            return
        from vtkmodules.util.numpy_support import vtk_to_numpy

        from tonguevis.render.scene import LIGHTS, TONGUE_MATERIAL
        from tonguevis.render.shading import shade

        camera = self.plotter.renderer.GetActiveCamera()
        view = np.array(camera.GetViewTransformMatrix().GetData()).reshape(4, 4)
        parallel = bool(camera.GetParallelProjection())
        lut = self.view_a.scene.lookup_table
        key = (view.tobytes(), parallel, self.frame_b, self.state.color, id(lut),
               None if lut is None else tuple(lut.GetTableRange()))
        if key == self._b_shaded:
            return
        nodes = self._b_nodes
        points = np.asarray(self._surface.points)[nodes]
        normals = np.asarray(self._surface.point_data["Normals"])[nodes]
        rgb = self._surface.GetPointData().GetArray("rgb")
        vtk_to_numpy(rgb)[nodes] = shade(self.b_colours(), normals, points, view, LIGHTS, parallel=parallel,
                                         **TONGUE_MATERIAL)
        rgb.Modified()
        self._b_shaded = key

    def _share_camera(self) -> None:
        """The panel looks through A's main camera (one vtkCamera): turning either view turns both."""
        camera = self.view_a.plotter.renderers[0].GetActiveCamera()
        self.plotter.renderer.SetActiveCamera(camera)
        if self._observed_camera is not camera:  # A's views may have been rebuilt with a new camera
            if self._observed_camera is not None:
                self._observed_camera.RemoveObserver(self._camera_observer)
            self._camera_observer = camera.AddObserver("ModifiedEvent", self._camera_moved)
            self._observed_camera = camera

    def _camera_moved(self, camera, _event) -> None:
        seen = (camera.GetPosition(), camera.GetFocalPoint(), camera.GetViewUp(), camera.GetParallelScale(),
                camera.GetViewAngle())
        if seen != self._camera_seen:  # a render's own clipping-range update is not a move
            self._camera_seen = seen
            QTimer.singleShot(0, self._repaint_both)

    def _repaint_both(self) -> None:
        self.plotter.interactor.update()
        self.view_a.plotter.interactor.update()

    # -- settings -----------------------------------------------------------------------------
    def set_layout(self, layout: str) -> None:
        """"side" (B in the panel's view) or "ghost" (B translucent in A's four views): into the app model."""
        if layout not in LAYOUTS:
            raise ValueError(f"compare layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
        self.state.set_compare_view(self, layout=layout)

    def set_time_mode(self, mode: str) -> None:
        """"production" or "absolute" (see :class:`~tonguevis.analysis.compare.Comparison`): into the app model."""
        if mode not in TIME_MODES:
            raise ValueError(f"compare time must be one of {', '.join(TIME_MODES)}, got {mode!r}")
        self.state.set_compare_view(self, time_mode=mode)

    def _on_compare_view(self, event) -> None:
        """The model's way of showing B changed (from here, a menu or a script): the controls show it, a new
        time mode compares afresh, a new layout shows or hides the panel's view."""
        view = event.value
        for box, key in ((self.layout_box, view.layout), (self.time_box, view.time_mode)):
            index = box.findData(key)
            if index != box.currentIndex():
                box.blockSignals(True)  # the box shows the model's choice: not a new choice
                box.setCurrentIndex(index)
                box.blockSignals(False)
        if self.comparison is not None and self.comparison.mode != view.time_mode and \
                not (view.time_mode == "production" and self.note):
            self.rebuild()
        else:
            self._apply_layout()
            self.show_time(self.state.time)

    def _apply_layout(self) -> None:
        layout = self.layout_mode
        self.plotter.interactor.setVisible(layout == "side")
        # The ghost needs no view of its own: the panel keeps its controls only.
        self.setMaximumWidth(16777215 if layout == "side" else GHOST_PANEL_WIDTH)

    # -- per frame -----------------------------------------------------------------------------
    def matched_frame(self, t_a: float) -> int | None:
        """B's frame shown with time ``t_a`` of A (None before both are simulated)."""
        return None if self.comparison is None else self.comparison.frame_b(t_a)

    def _on_frame_drawn(self, event) -> None:
        """A drew frame ``event.value``: B is drawn for the same moment (its own view, or the ghost A draws)."""
        if event.source is not self.view_a:
            return
        self.show_frame(event.value)

    def _on_playing(self, event) -> None:
        interactor = self.plotter.interactor
        if hasattr(interactor, "set_pipelined"):
            interactor.set_pipelined(event.value)

    def show_time(self, t_a: float) -> None:
        """Show B at the moment matched with A's time ``t_a``."""
        if self.comparison is None or self._surface is None or not self.isVisible():
            return
        self.show_frame(self.session_a.frames.frame_at(t_a))

    def show_frame(self, i: int) -> None:
        """Show B at the moment matched with A's frame ``i``."""
        if self.comparison is None or self._surface is None or not self.isVisible():
            return
        from tonguevis.render.drawing import draw_frame

        session_a, session_b = self.session_a, self.session_b
        t_a = float(session_a.frames.times[i])
        j = self.comparison.frame_b(t_a)
        reference = self.state.reference
        difference = self.state.color == "difference" and self._clim is not None
        drawn = draw_frame(session_b, j, reference, "plain" if difference else self.state.color)
        self._surface.points[:] = drawn.points
        self._surface.point_data["Normals"][:] = self._normals(drawn.points)
        if len(drawn.sensor_points):
            self._sensors.points[:] = drawn.sensor_points
        self._b_values = self.shown.difference(i) if difference else drawn.scalars
        self.frame_b = j
        self._b_shaded = None  # new points or values: lit again as the view renders
        self.caption.setText(self._caption(session_a, i, session_b, j))
        if self.layout_mode == "side":
            request = getattr(self.plotter.interactor, "request_render", None)
            if request is not None:
                request(tag=t_a)
            else:
                self.plotter.interactor.update()
        # The ghost is in A's views, which render after their frame hooks.
        self.renders += 1

    def _caption(self, session_a, i: int, session_b, j: int) -> str:
        times_b = session_b.frames.times
        text = f"B at t = {times_b[j]:.3f} s, {frame_label(j, len(times_b))}"
        phase = self.comparison.phase(float(session_a.frames.times[i]))
        if phase is not None and phase[0] > self.comparison.productions_in_b():
            held = "held on its last frame" if j == len(times_b) - 1 else "running on past its last production"
            text += (f"   ·   A: production {phase[0]}, {100 * phase[1]:.0f} % through   ·   "
                     f"B has no production {phase[0]} (it has {self.comparison.productions_in_b()}): {held}")
        elif phase is not None:
            text += f"   ·   production {phase[0]}, {100 * phase[1]:.0f} % through (both)"
        elif self.comparison.mode == "production":
            text += "   ·   between productions"
        else:
            text += "   ·   absolute time"
        if not self.comparison.same_mesh:
            text += "   ·   other tongue mesh: no per-node distance"
        if self.note:
            text += f"\n{self.note}"
        return text

    def close_view(self) -> None:
        self.plotter.close()


def _background() -> str:
    from tonguevis.render.scene import BACKGROUND

    return BACKGROUND if isinstance(BACKGROUND, str) else BACKGROUND[0]
