"""The 3D scene: the tongue surface, sensors, EMA markers, jaw and palate (pyvista, no Qt).

One plotter with four renderers in a ``"1|3"`` layout: the main view on the
left and three small orthographic views (top, front, lateral) on the right.
All four draw the *same* datasets, so one in-place update of the points and
scalars and one ``render()`` moves every view to the same frame.  The same
class drives the window's ``QtInteractor`` and the off-screen plotter of the
video export.

Every surface is lit on the CPU at its vertices (:mod:`tonguevis.render.shading`)
and drawn unlit: under software OpenGL, VTK's per-pixel lighting of the large
translucent jaw and palate and of four tongues cost a third of a frame.  Each
view has its own colours (the lights follow each view's camera), recomputed
just before that view renders when the surface, its colouring or the camera
changed; the four views share the tongue's points.
"""

from __future__ import annotations

import numpy as np

import pyvista as pv

from tonguevis.render.shading import shade
from tonguevis.render.surface_geometry import VertexNormals, hidden_side, outward_normals

MAIN, TOP, FRONT, LATERAL = 0, 1, 2, 3
VIEW_NAMES = {TOP: "top", FRONT: "front", LATERAL: "lateral (right side)"}
#: Camera direction (from the focal point towards the camera) and view-up of each view;
#: frame: x anterior, y left, z up.  Lateral looks from the right so anterior is on the right.
CAMERAS = {
    MAIN: ((0.55, -1.0, 0.55), (0.0, 0.0, 1.0)),
    TOP: ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0)),
    FRONT: ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    LATERAL: ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
}
CONTEXT_VIEWS = (MAIN, LATERAL)
TONGUE_COLOUR = "#d98a8a"
SENSOR_COLOUR = "#2ecc71"
TARGET_COLOUR = "#ffd23f"
CONTEXT_COLOUR = "#e8e2d0"
#: A speaker's own palate stands out from the generic context (colour, opacity in the main view).
SPEAKER_PALATE_STYLE = ("#8fc1e3", 0.3)
COLORMAP = "plasma"
#: The part of :data:`COLORMAP` used: its dark-purple low end (#0d0887) merged with the
#: background (contrast 1.14); from 0.25 on it starts at #7e03a8 (contrast 1.55 to the background).
COLORMAP_RANGE = (0.25, 1.0)
#: Distance to the palate: red where the tongue touches it, blue far below; magenta inside it;
#: a neutral light grey where no palate lies above (outside a traced palate's footprint): the
#: tongue's own pink, lit from the side, read as the dark red of contact.
CONTACT_COLORMAP = "RdYlBu"
INSIDE_COLOUR = "#ff00ff"
NO_PALATE_COLOUR = "#c8c8c8"
#: One flat colour, the middle of the old gradient (#20242c to #3b4252): a gradient background
#: is drawn per pixel in every view (a sixth of a frame under software OpenGL), a flat one is a clear.
BACKGROUND = "#2b303a"
#: Two lights (a key light above and to the right of the camera, and a head light) instead of
#: pyvista's five-light kit: under software OpenGL each light is paid per pixel, and the kit's
#: two back lights and fill light add little to a surface seen from the front.  (direction
#: in camera coordinates, intensity); the head light has no direction.
LIGHTS = (((0.6, 0.8, 1.0), 0.75), (None, 0.45))
#: The tongue's material (VTK's: ambient, diffuse, specular, specular power) and the shells'.
TONGUE_MATERIAL = dict(ambient=0.0, diffuse=1.0, specular=0.3, specular_power=15.0)
CONTEXT_MATERIAL = dict(ambient=0.0, diffuse=1.0, specular=0.0, specular_power=1.0)
#: Opacity of a closed shell (jaw, palate) in the main view: drawn with its back faces culled,
#: one layer of it shows where two (near and far wall) used to, so 0.2 ≈ 1 - (1 - 0.12)².
CONTEXT_OPACITY = 0.2
#: The colour bar at the main view's right edge (fractions of the view) and the room kept for it (a
#: shift of the main camera's window centre, VTK's units: 2 = the view's width):
#: the main camera centres the tongue in the rest of the view, so the bar's numbers never sit on
#: the tongue's tip (which points right, anterior).
COLOUR_BAR = dict(position_x=0.915, position_y=0.25, width=0.03, height=0.5)
COLOUR_BAR_ROOM = 0.06
#: The main view's zoom after fitting the tongue (1 = VTK's fit, which leaves a wide margin).
MAIN_ZOOM = 1.2
#: Caption font sizes in pixels (the time and frame in the main view, the direction in the small ones).
CAPTION_PX = {"main": 15, "small": 12}


class Caption:
    """Text in a view's upper-left corner with a fixed font size.

    A vtkCornerAnnotation fits its font to the view every time its text changes
    (about 30 ms a frame for the frame caption under software OpenGL); this
    vtkTextActor only lays out its new text.  ``GetText(2)``/``SetText(2, text)``
    as the corner annotation's upper-left corner.
    """

    def __init__(self, plotter, text: str, size_px: int, name: str, colour: str = "white"):
        import vtk

        self.actor = vtk.vtkTextActor()
        self.actor.SetInput(text)
        self._text, self._size_px = text, int(size_px)
        # Wrapped to the view's width at each render where it changed: a narrow view (1280 pixels, a
        # recording compared beside) cut "head frame: tongue and jaw move with the jaw, palate fixed".
        self._renderer, self._width = plotter.renderer, -1
        self._renderer.AddObserver("StartEvent", lambda *_args: self._fit())
        prop = self.actor.GetTextProperty()
        prop.SetFontSize(int(size_px))
        prop.SetColor(pv.Color(colour).float_rgb)
        prop.SetVerticalJustificationToTop()
        prop.SetJustificationToLeft()
        prop.SetFontFamilyToArial()
        coordinate = self.actor.GetPositionCoordinate()
        coordinate.SetCoordinateSystemToNormalizedViewport()
        coordinate.SetValue(0.006, 0.99)
        plotter.add_actor(self.actor, reset_camera=False, name=name, pickable=False)

    def GetText(self, _corner: int = 2) -> str:  # noqa: N802 (the corner annotation's name)
        """The text as set (:meth:`shown_text`: as drawn, wrapped to the view)."""
        return self._text

    def SetText(self, _corner: int, text: str) -> None:  # noqa: N802
        if text != self._text:
            self._text = text
            self._width = -1
            self._fit()

    def shown_text(self) -> str:
        return self.actor.GetInput() or ""

    def _fit(self) -> None:
        width = int(self._renderer.GetSize()[0])
        if width == self._width:
            return
        self._width = width
        shown = wrap_to_pixels(self._text, width - 12, self._size_px) if width > 0 else self._text
        if shown != self.shown_text():
            self.actor.SetInput(shown)

    def SetVisibility(self, visible: bool) -> None:  # noqa: N802
        self.actor.SetVisibility(visible)


#: Width of a character of the views' sans-serif font, as a fraction of its size in pixels: a generous
#: average (Arial's lower case is about 0.5), so that a wrapped line never runs past the edge.
CHAR_WIDTH = 0.6


def wrap_to_pixels(text: str, width_px: float, size_px: float) -> str:
    """``text`` with each line wrapped at word boundaries (a word longer than a line hyphenated) so that
    it is at most ``width_px`` wide in the views' font of ``size_px`` pixels."""
    import textwrap

    chars = max(int(width_px / (CHAR_WIDTH * size_px)), 4)
    lines = []
    for line in text.split("\n"):
        words = []
        for word in line.split(" "):  # a word longer than a line: hyphenated pieces
            while len(word) > chars:
                words.append(word[:chars - 1] + "-")
                word = word[chars - 1:]
            words.append(word)
        lines.extend(textwrap.wrap(" ".join(words), chars, break_long_words=False, break_on_hyphens=True) or [""])
    return "\n".join(lines)


def set_lights(renderer) -> None:
    """Replace ``renderer``'s lights by :data:`LIGHTS`."""
    import vtk

    renderer.RemoveAllLights()
    for direction, intensity in LIGHTS:
        light = vtk.vtkLight()
        if direction is None:
            light.SetLightTypeToHeadlight()
        else:
            light.SetLightTypeToCameraLight()
            light.SetPosition(*direction)
            light.SetFocalPoint(0.0, 0.0, 0.0)
        light.SetIntensity(intensity)
        renderer.AddLight(light)


def faces_to_vtk(faces: np.ndarray) -> np.ndarray:
    """(f, 3) triangles -> VTK's flat cell array [3, a, b, c, 3, ...]."""
    faces = np.asarray(faces, dtype=np.int64)
    return np.hstack([np.full((len(faces), 1), 3, dtype=np.int64), faces]).ravel()


def sharing_geometry(surface: pv.PolyData) -> pv.PolyData:
    """A PolyData drawing ``surface``'s points and triangles (the same VTK objects: writing
    ``surface.points`` in place moves both), with point data of its own (a view's colours)."""
    view = pv.PolyData()
    view.SetPoints(surface.GetPoints())
    view.SetPolys(surface.GetPolys())
    return view


def _faces_of(surface: pv.PolyData) -> np.ndarray:
    """(f, 3) triangles of a triangulated PolyData."""
    return np.asarray(surface.faces).reshape(-1, 4)[:, 1:]


class TongueScene:
    """The tongue scene on ``plotter`` (a pyvista Plotter or QtInteractor of shape "1|3")."""

    def __init__(self, plotter):
        self.plotter = plotter
        self.surface: pv.PolyData | None = None
        self.sensors: pv.PolyData | None = None
        self.targets: pv.PolyData | None = None
        self.residuals: pv.PolyData | None = None
        self.surface_actors: list = []
        self.context_actors: list = []
        self.context: dict[str, pv.PolyData] = {}
        self._context_rest: dict[str, np.ndarray] = {}
        self._context_offsets: dict[str, np.ndarray] = {}
        self.view_labels: dict[int, object] = {}
        self.context_visible = True
        self.scalar_bar = None
        self.time_text = None
        self._normals: VertexNormals | None = None
        self._mode = "plain"
        self._clim: dict[str, tuple[float, float]] = {}
        self._titles: dict[str, str] = {}
        #: Per view: the tongue's PolyData with that view's colours, and the shells' (name -> PolyData).
        self._tongue_views: dict[int, pv.PolyData] = {}
        self._context_views: dict[int, dict[str, pv.PolyData]] = {}
        self._context_normals: dict[str, np.ndarray] = {}
        self._context_hidden: dict[str, str | None] = {}  # name -> the faces a shell skips (None: open)
        self._shaded: dict[tuple, tuple] = {}  # (view, surface name) -> what its colours were computed from
        self._style = 0  # bumped when the colouring changes (mode, range, lookup table)
        self._lut = None
        self._colours = None  # (what they were computed from, (colours, normals, points)) of the surface nodes
        #: The nodes on the tongue's surface, the only ones lit and drawn.
        self.shaded_nodes = np.zeros(0, dtype=np.int64)
        plotter.set_background(BACKGROUND)
        for index, renderer in enumerate(plotter.renderers):
            # Plain alpha blending for the jaw and palate: VTK's order-independent
            # transparency costs extra full-screen passes (3x the frame under software GL),
            # and two convex-ish context shells need no exact ordering.
            renderer.SetUseOIT(False)
            # Every prop is in view: VTK's frustum culler only brought each moving prop's pipeline
            # and bounds up to date before every render (1-2.7 of the four views' 9-11 ms of
            # draw calls, measured on the demo under software GL).
            renderer.GetCullers().RemoveAllItems()
            set_lights(renderer)
            renderer.AddObserver("StartEvent", lambda *_a, index=index: self.shade_view(index))

    def _each_view(self):
        for index in (MAIN, TOP, FRONT, LATERAL):
            self.plotter.subplot(index)
            yield index

    # -- building --------------------------------------------------------------------
    def build(self, points: np.ndarray, faces: np.ndarray, n_sensors: int = 0,
              context: dict[str, pv.PolyData] | None = None,
              clim: dict[str, tuple[float, float]] | None = None,
              titles: dict[str, str] | None = None,
              context_style: dict[str, tuple[str, float]] | None = None) -> None:
        """(Re)create every actor: called once per model or motion, never per frame.

        points : (n, 3) node positions (metres); faces : (f, 3) boundary triangles;
        n_sensors : driving sensors (spheres, markers and residual lines);
        context : rigid surfaces (jaw, palate) drawn transparent, moved per frame by
        :meth:`update`'s ``context_offsets``; context_style : name -> (colour, opacity)
        for those not in the default style;
        clim / titles : colour range and colour-bar title of each scalar mode
        ("contact" gets the distance-to-palate colour map).
        """
        plotter = self.plotter
        for index in self._each_view():
            plotter.renderer.clear_actors()
        # clear_actors drops the bar's actor but pyvista still remembers the title and would
        # hand back None instead of a new bar: forget it too (a second recording must open).
        plotter.scalar_bars.clear()
        self._clim = dict(clim or {})
        self._titles = dict(titles or {})
        self.context = dict(context or {})
        self._context_rest = {name: np.array(surface.points, dtype=np.float32) for name, surface in self.context.items()}
        self._context_offsets = {name: np.zeros(3) for name in self.context}
        self.view_labels = {}
        self._luts = {"contact": _contact_lut(self._clim.get("contact", (0.0, 1.0))),
                      "default": pv.LookupTable(cmap=colour_map(), n_values=256)}
        self._context_normals = {name: outward_normals(surface.points, _faces_of(surface))
                                 for name, surface in self.context.items()}
        self._context_hidden = {name: hidden_side(surface.points, _faces_of(surface))
                                for name, surface in self.context.items()}
        self._tongue_views, self._context_views, self._shaded, self._colours = {}, {}, {}, None
        self.shaded_nodes = np.unique(np.asarray(faces, dtype=np.int64))
        points = np.asarray(points, dtype=np.float32)
        # The tongue is closed and opaque: its far side is hidden by its near side, and not
        # rasterising it saves a fifth of a frame under software OpenGL.
        tongue_hidden = hidden_side(points, faces)
        # Shading normals point out of the tongue whichever way its triangles are wound.
        self._normals = VertexNormals(np.asarray(faces)[:, ::-1] if tongue_hidden == "front" else faces, len(points))
        self.surface = pv.PolyData(points.copy(), faces_to_vtk(faces))
        self.surface.point_data["value"] = np.zeros(len(points), dtype=np.float32)
        self.surface.point_data["Normals"] = self._normals(points)
        self.surface.point_data.active_normals_name = "Normals"
        self.sensors = pv.PolyData(np.zeros((max(n_sensors, 1), 3), dtype=np.float32))
        self.targets = pv.PolyData(np.zeros((max(n_sensors, 1), 3), dtype=np.float32))
        self.residuals = pv.PolyData(np.zeros((2 * max(n_sensors, 1), 3), dtype=np.float32))
        s = max(n_sensors, 1)
        self.residuals.lines = np.column_stack([np.full(s, 2), np.arange(s), np.arange(s) + s]).ravel()
        self.surface_actors = []
        self.context_actors = []
        for index in self._each_view():
            main = index == MAIN
            tongue = self._tongue_views[index] = sharing_geometry(self.surface)
            tongue.point_data["rgb"] = np.zeros((len(points), 3), dtype=np.uint8)
            # Lit at the vertices (shade_view), drawn unlit: colours interpolated between nodes.
            actor = add_lit_surface(plotter, tongue, f"tongue{index}", cull=tongue_hidden)
            self.surface_actors.append(actor)
            if n_sensors:
                plotter.add_mesh(self.sensors, color=SENSOR_COLOUR, point_size=14 if main else 8,
                                 render_points_as_spheres=True, name=f"sensors{index}", reset_camera=False)
                plotter.add_mesh(self.targets, color=TARGET_COLOUR, point_size=9 if main else 5,
                                 render_points_as_spheres=True, name=f"targets{index}", reset_camera=False)
                plotter.add_mesh(self.residuals, color=TARGET_COLOUR, line_width=2,
                                 name=f"residuals{index}", reset_camera=False)
            # Transparent context costs a second render pass per view (most of a frame under
            # software OpenGL): draw it where it tells most, the main and the lateral views.
            # A closed shell is drawn without its back faces: its far wall behind its near one
            # doubled the translucent pixels, the costliest part of a frame under software GL.
            self._context_views[index] = {}
            for name, surface in self.context.items() if index in CONTEXT_VIEWS else ():
                colour, opacity = (context_style or {}).get(name, (CONTEXT_COLOUR, CONTEXT_OPACITY))
                shell = self._context_views[index][name] = sharing_geometry(surface)
                shell.point_data["rgb"] = np.zeros((surface.n_points, 3), dtype=np.uint8)
                shell.field_data["colour"] = np.asarray(pv.Color(colour).float_rgb)
                context_actor = add_lit_surface(plotter, shell, f"{name}{index}",
                                                 opacity=opacity if main else 0.8 * opacity,
                                                 cull=self._context_hidden[name])
                context_actor.SetVisibility(self.context_visible)
                self.context_actors.append(context_actor)
            if main:
                from pyvista.plotting.mapper import DataSetMapper

                bar_mapper = DataSetMapper(self.surface)
                bar_mapper.lookup_table = self._luts["default"]
                self.scalar_bar = plotter.add_scalar_bar(
                    title="", mapper=bar_mapper, vertical=True, n_labels=4, fmt="%.3g", **COLOUR_BAR,
                    title_font_size=12, label_font_size=11,
                )
                self.scalar_bar.SetVerticalTitleSeparation(8)
                self._bar_fitted = None
                plotter.renderer.AddObserver("StartEvent", lambda *_args: self._fit_bar_title())
                self.time_text = Caption(plotter, "", CAPTION_PX["main"], "time")
                if n_sensors:
                    plotter.add_text("sensor node", position=(8, 26), font_size=8, name="legend_s",
                                     color=SENSOR_COLOUR)
                    plotter.add_text("measured EMA (line = residual)", position=(8, 8), font_size=8,
                                     name="legend_t", color=TARGET_COLOUR)
            else:
                self.view_labels[index] = Caption(plotter, VIEW_NAMES[index], CAPTION_PX["small"], f"label{index}")
                plotter.enable_parallel_projection()
        self.reset_cameras()
        self.set_mode(self._mode)

    # -- per frame -------------------------------------------------------------------
    def update(self, points: np.ndarray, scalars: np.ndarray | None = None,
               sensor_points: np.ndarray | None = None, targets: np.ndarray | None = None,
               text: str | None = None, render: bool = True,
               context_offsets: dict[str, np.ndarray] | None = None,
               context_shapes: dict[str, np.ndarray] | None = None) -> None:
        """Move to one frame: write points/scalars in place, then one render.

        context_offsets : name -> (3,) translation of a context surface from where it was
        built (the jaw carried by the jaw's motion in the head frame, the palate by minus
        it in the jaw frame); surfaces not named stay where they are.
        context_shapes : name -> (k, 3) the surface's points before its offset, where it changes shape (the velum
        lifting frame by frame); same number of points as built.
        """
        if self.surface is None:
            return
        for name, shape in (context_shapes or {}).items():
            self.reshape_context(name, shape)
        for name, offset in (context_offsets or {}).items():
            self.move_context(name, offset)
        self.surface.points[:] = points
        self.surface.point_data["Normals"][:] = self._normals(points)
        if scalars is not None:
            self.surface.point_data["value"][:] = scalars
        if sensor_points is not None and len(sensor_points):
            self.sensors.points[:] = sensor_points
            self.targets.points[:] = targets
            s = len(sensor_points)
            self.residuals.points[:s] = sensor_points
            self.residuals.points[s:] = targets
        if text is not None and self.time_text is not None:
            self.time_text.SetText(2, text)  # vtkCornerAnnotation: 2 = upper left
        if render:
            self.plotter.render()

    def reshape_context(self, name: str, points: np.ndarray) -> None:
        """Give context surface ``name`` the shape ``points`` (k, 3) m (before its offset), in place."""
        if name not in self.context:
            return
        points = np.asarray(points, dtype=np.float32)
        if points.shape != self._context_rest[name].shape or np.array_equal(points, self._context_rest[name]):
            return
        self._context_rest[name] = points.copy()
        self.context[name].points[:] = points + np.asarray(self._context_offsets[name], dtype=np.float32)

    def move_context(self, name: str, offset: np.ndarray) -> None:
        """Translate context surface ``name`` to ``offset`` (3,) m from where it was built, in place."""
        offset = np.asarray(offset, dtype=np.float64)
        if name not in self.context or np.array_equal(offset, self._context_offsets[name]):
            return
        self.context[name].points[:] = self._context_rest[name] + offset.astype(np.float32)
        self._context_offsets[name] = offset.copy()

    def context_offset(self, name: str) -> np.ndarray:
        """(3,) the current translation of context surface ``name`` from where it was built."""
        return self._context_offsets[name].copy()

    def set_view_labels(self, suffix: str) -> None:
        """Caption the small views with their direction and ``suffix`` (e.g. the frame of reference)."""
        for index, actor in self.view_labels.items():
            actor.SetText(2, f"{VIEW_NAMES[index]}{suffix}")  # vtkCornerAnnotation: 2 = upper left

    def _fit_bar_title(self) -> None:
        """The colour bar's title wrapped to the room its view leaves it: VTK centres it over the bar near
        the view's right edge, and a narrow view cut "displacement" to "displaceme"."""
        bar = self.scalar_bar
        if bar is None:
            return
        renderer = self.plotter.renderers[MAIN]
        width = int(renderer.GetSize()[0])
        if width <= 0 or self._bar_fitted == (width, self._mode):
            return
        self._bar_fitted = (width, self._mode)
        centre = COLOUR_BAR["position_x"] * width  # (measured: the title is centred on the bar's left edge)
        room = 2 * (width - centre) - 6
        title = self._titles.get(self._mode, "")
        bar.SetTitle(wrap_to_pixels(title, room, bar.GetTitleTextProperty().GetFontSize()))

    def set_mode(self, mode: str) -> None:
        """Colour by ``mode`` ('displacement', 'energy', 'contact' or 'plain')."""
        self._mode = mode
        self._style += 1
        plain = mode not in self._clim
        contact = mode == "contact" and not plain
        luts = getattr(self, "_luts", {})
        lut = luts.get("contact") if contact else luts.get("default")
        self._lut = None if plain else lut
        if lut is not None and not plain:
            lut.scalar_range = self._clim[mode]
        if self.scalar_bar is not None:
            self.scalar_bar.SetVisibility(not plain)
            self.scalar_bar.SetTitle(self._titles.get(mode, ""))
            self._bar_fitted = None
            self._fit_bar_title()
            if lut is not None:
                self.scalar_bar.SetLookupTable(lut)
            self.scalar_bar.SetDrawBelowRangeSwatch(contact)
            self.scalar_bar.SetDrawNanAnnotation(contact)
            self.scalar_bar.SetBelowRangeAnnotation("inside")
            self.scalar_bar.SetNanAnnotation("no palate above")

    def set_colour_range(self, mode: str, clim: tuple[float, float], title: str) -> None:
        """Offer colouring ``mode`` with range ``clim`` and scalar-bar ``title`` (e.g. the compare
        view's distance to the other tongue); applied now if it is the mode shown."""
        self._clim[mode] = tuple(clim)
        self._titles[mode] = title
        if self._mode == mode:
            self.set_mode(mode)

    def set_context_visible(self, visible: bool) -> None:
        """Show or hide the jaw and palate (hiding them triples the frame rate under software GL)."""
        self.context_visible = bool(visible)
        for actor in self.context_actors:
            actor.SetVisibility(self.context_visible)

    @property
    def mode(self) -> str:
        return self._mode

    @property
    def lookup_table(self):
        """The lookup table colouring the tongue (its range the mode's), None when plain."""
        return self._lut

    # -- shading ---------------------------------------------------------------------
    def tongue_colours(self) -> np.ndarray:
        """(m, 3) the unlit colours in [0, 1] of the tongue's surface nodes (:attr:`shaded_nodes`):
        its scalars through the lookup table, or the plain tongue colour."""
        return self._tongue_state()[0]

    def _tongue_state(self) -> tuple:
        """The surface nodes' (colours, normals, positions) for this frame, computed once for the
        four views (when the surface, its scalars or the colouring changed)."""
        key = (self.surface.GetMTime(), self._style)
        if self._colours is not None and self._colours[0] == key:
            return self._colours[1]
        from vtkmodules.util.numpy_support import vtk_to_numpy

        nodes = self.shaded_nodes
        data = self.surface.GetPointData()
        if self._lut is None:
            colours = np.broadcast_to(np.asarray(pv.Color(TONGUE_COLOUR).float_rgb), (len(nodes), 3))
        else:
            colours = mapped_colours(self._lut, vtk_to_numpy(data.GetArray("value"))[nodes])
        normals = vtk_to_numpy(data.GetArray("Normals"))[nodes]
        points = vtk_to_numpy(self.surface.GetPoints().GetData())[nodes]
        self._colours = (key, (colours, normals, points))
        return self._colours[1]

    def _camera_state(self, index: int) -> tuple:
        """(world-to-view matrix (4, 4), parallel projection) of view ``index``'s camera."""
        camera = self.plotter.renderers[index].GetActiveCamera()
        return np.array(camera.GetViewTransformMatrix().GetData()).reshape(4, 4), bool(camera.GetParallelProjection())

    def shade_view(self, index: int) -> None:
        """Light view ``index``'s tongue and shells for its camera, where anything they depend on
        changed (called as the view starts rendering).  The tongue moves every frame: the first
        view to render lights every view's tongue whose light is out of date, in one pass."""
        if self.surface is None or index not in self._tongue_views or index >= len(self.surface_actors):
            return  # not built yet (a view may render while build() adds its actors)
        view, parallel = self._camera_state(index)
        # The camera's own MTime changes at every render (its clipping range is reset): the
        # view matrix is what the lighting depends on.
        seen = (view.tobytes(), parallel, self._style)
        self._shade_tongues()  # nothing to do when the first view to render lit them all
        if not self.context_visible:
            return
        from vtkmodules.util.numpy_support import vtk_to_numpy

        for name, shell in self._context_views.get(index, {}).items():
            # A closed shell without highlights is lit the same wherever it is moved to.
            closed = self._context_hidden[name] is not None
            moves = not closed or CONTEXT_MATERIAL["specular"] > 0.0
            key = seen + ((self.context[name].GetMTime(),) if moves else ())
            if self._shaded.get((index, name)) == key:
                continue
            colour = vtk_to_numpy(shell.GetFieldData().GetArray("colour"))
            shell.point_data["rgb"][:] = shade(
                colour, self._context_normals[name], self.context[name].points, view, LIGHTS,
                parallel=parallel, two_sided=not closed, **CONTEXT_MATERIAL)
            self._shaded[(index, name)] = key

    def _shade_tongues(self) -> None:
        """Light the tongue in every view whose colours are out of date (all at once)."""
        from vtkmodules.util.numpy_support import vtk_to_numpy

        mtime = self.surface.GetMTime()
        stale, views, parallels, keys = [], [], [], []
        for index in self._tongue_views:
            if index >= len(self.surface_actors) or not self.surface_actors[index].GetVisibility():
                continue
            view, parallel = self._camera_state(index)
            key = (view.tobytes(), parallel, self._style, mtime)
            if self._shaded.get((index, "tongue")) != key:
                stale.append(index)
                views.append(view)
                parallels.append(parallel)
                keys.append(key)
        if not stale:
            return
        colours, normals, points = self._tongue_state()
        lit = shade(colours, normals, points, np.array(views), LIGHTS, parallel=parallels, **TONGUE_MATERIAL)
        for k, index in enumerate(stale):
            rgb = self._tongue_views[index].GetPointData().GetArray("rgb")
            vtk_to_numpy(rgb)[self.shaded_nodes] = lit[k]
            rgb.Modified()
            self._shaded[(index, "tongue")] = keys[k]

    def reset_cameras(self) -> None:
        """Put every view back to its standard direction, fitted to the scene."""
        if self.surface is None:
            return
        bounds = np.array(self.surface.bounds, dtype=float).reshape(3, 2)
        centre = bounds.mean(axis=1)
        size = float(np.linalg.norm(bounds[:, 1] - bounds[:, 0])) or 0.1
        for index in self._each_view():
            direction, up = CAMERAS[index]
            direction = np.asarray(direction, dtype=float)
            direction /= np.linalg.norm(direction)
            camera = self.plotter.renderer.camera
            camera.focal_point = centre
            camera.position = centre + direction * size * 2.2
            camera.up = up
            # Fit the tongue (not the markers, whose buffers may still be empty).
            self.plotter.renderer.reset_camera(bounds=bounds.ravel())
            if index != MAIN:
                camera.parallel_scale = 0.5 * size * 0.75
            else:
                camera.zoom(MAIN_ZOOM)
                # Shift the picture left by half the bar's room: the tongue centred beside the bar.
                camera.SetWindowCenter(COLOUR_BAR_ROOM, 0.0)
        self.plotter.subplot(MAIN)


def colour_map():
    """The tongue's colour map: :data:`COLORMAP` over :data:`COLORMAP_RANGE` (a matplotlib colormap)."""
    import matplotlib
    from matplotlib.colors import ListedColormap

    low, high = COLORMAP_RANGE
    return ListedColormap(matplotlib.colormaps[COLORMAP](np.linspace(low, high, 256)), name=f"{COLORMAP}_part")


def contrast_ratio(colour_a, colour_b) -> float:
    """WCAG contrast ratio (1-21) of two colours (anything :class:`pyvista.Color` reads)."""
    def luminance(colour) -> float:
        c = np.asarray(pv.Color(colour).float_rgb)
        c = np.where(c <= 0.03928, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
        return float(c @ [0.2126, 0.7152, 0.0722])

    light, dark = sorted((luminance(colour_a), luminance(colour_b)), reverse=True)
    return (light + 0.05) / (dark + 0.05)


def mapped_colours(lut, values: np.ndarray) -> np.ndarray:
    """(n, 3) colours in [0, 1] of ``values`` (n,) through the VTK lookup table ``lut`` (its range)."""
    import vtk
    from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy

    values = np.ascontiguousarray(values, dtype=np.float32)
    # MapScalars reads the "no palate above" (NaN) and "inside" (below range) colours from
    # entries that only Build() brings up to date after they are set.
    lut.Build()
    mapped = lut.MapScalars(numpy_to_vtk(values), vtk.VTK_COLOR_MODE_MAP_SCALARS, -1, vtk.VTK_RGB)
    return vtk_to_numpy(mapped).reshape(len(values), 3) / 255.0


def add_lit_surface(plotter, surface: pv.PolyData, name: str, opacity: float = 1.0, cull: str | None = None):
    """Add ``surface`` drawn unlit in the colours of its "rgb" point array (lit by
    :meth:`TongueScene.shade_view`) to the plotter's active view; returns the actor.
    ``cull``: the faces not drawn ("back", "front" or None, see :func:`hidden_side`).

    The mapper reads the array itself: pyvista's ``add_mesh(scalars=...)`` puts a Python
    algorithm before the mapper that copies the surface every time it changes (every frame).
    """
    from pyvista.plotting.mapper import DataSetMapper

    mapper = DataSetMapper()
    mapper.SetInputData(surface)
    mapper.SetScalarModeToUsePointFieldData()
    mapper.SelectColorArray("rgb")
    mapper.SetColorModeToDirectScalars()
    mapper.ScalarVisibilityOn()
    actor = pv.Actor(mapper=mapper)
    actor.prop.lighting = False
    actor.prop.opacity = opacity
    actor.prop.SetBackfaceCulling(cull == "back")
    actor.prop.SetFrontfaceCulling(cull == "front")
    plotter.add_actor(actor, reset_camera=False, name=name, pickable=False)
    return actor


def _contact_lut(clim: tuple[float, float]) -> "pv.LookupTable":
    """Distance to the palate: red (touching) to blue (far); inside the palate and no palate above in their own colours."""
    lut = pv.LookupTable(cmap=CONTACT_COLORMAP, n_values=256)
    lut.scalar_range = clim
    lut.below_range_color = INSIDE_COLOUR
    lut.nan_color = NO_PALATE_COLOUR
    return lut


# -- what the four views show for a simulated session (the app's views and the video alike) -----------
def context_surfaces(palate=None, model=None) -> dict:
    """Jaw and palate surfaces shipped in meshes/ (empty if absent or unreadable); ``palate``
    (a :class:`~tonguevis.render.drawing.ShownPalate`) replaces the shipped palate.  They belong to
    the shipped tongue's frame: placed with ``model`` when it is placed in a speaker
    (:mod:`tonguevis.sim.placement`)."""
    from tonguevis._logging import logger as log
    from tonguevis.paths import MESH_DIR
    from tonguevis.sim.placement import model_placement

    placement = model_placement(model)
    out = {}
    try:
        from tonguevis.mesh import read_surface
    except ImportError:
        return out
    for name in ("jaw", "palate"):
        for path in sorted(MESH_DIR.glob(f"{name}.*")):
            try:
                points, faces = _as_points_faces(read_surface(path))
            except Exception as exc:  # context is optional: never block the app on it
                log.warning("context surface %s not shown: %s", path, exc)
                continue
            if placement is not None:
                points = placement.apply(points)
            out[name] = pv.PolyData(np.asarray(points, dtype=np.float32), faces_to_vtk(faces))
            break
    if palate is not None and not palate.generic:
        out["palate"] = pv.PolyData(np.asarray(palate.points, dtype=np.float32), faces_to_vtk(palate.faces))
    return out


def _as_points_faces(surface):
    if isinstance(surface, tuple):
        return surface[0], surface[1]
    for names in (("points", "faces"), ("vertices", "faces"), ("points", "triangles")):
        if all(hasattr(surface, n) for n in names):
            return getattr(surface, names[0]), getattr(surface, names[1])
    raise TypeError(f"unknown surface type {type(surface).__name__}")


def surface_faces(model) -> np.ndarray:
    """(f, 3) int triangles of the model's surface (its ``surface_faces``, else the mesh's boundary)."""
    faces = getattr(model, "surface_faces", None)
    if callable(faces):
        faces = faces()
    return np.asarray(faces if faces is not None else model.mesh.boundary_faces())


def scene_titles() -> dict[str, str]:
    """Colour-bar title per colouring, with its unit."""
    from tonguevis.render.frames import SCALARS

    titles = {name: f"{label}\n({unit})" for name, (label, unit) in SCALARS.items()}
    titles["contact"] = "distance to\npalate (mm)"
    return titles


def scene_setup(session) -> dict:
    """The keyword arguments of :meth:`TongueScene.build` for a simulated session (window and video alike)."""
    from tonguevis.render.drawing import CONTACT_RANGE_MM

    frames = session.frames
    palate = getattr(session, "shown_palate", None)
    clim = dict(frames.clim)
    if palate is not None:
        clim["contact"] = CONTACT_RANGE_MM
    style = {} if palate is None or palate.generic else {"palate": SPEAKER_PALATE_STYLE}
    return dict(n_sensors=len(frames.motion.sensor_names), context=context_surfaces(palate, frames.motion.model), clim=clim,
                titles=scene_titles(), context_style=style)


def frame_text(frames, i: int, productions, caption: str | None = None) -> str:
    """The main view's caption at frame ``i``: time, frame number, production, largest sensor residual (mm)."""
    from tonguevis.render.production_marks import interval_at
    from tonguevis.sim.motion import frame_label

    t = frames.times[i]
    text = f"t = {t:.3f} s   {frame_label(i, frames.n_frames)}"
    production = interval_at(productions, t)
    if production is not None:
        text += f"   production {productions.index(production) + 1}"
    residual = getattr(frames.motion, "sensor_residual", None)
    if residual is not None and len(residual):
        text += f"\nsensor residual max {1e3 * float(np.nanmax(residual[i])):.2f} mm"
    if caption:
        text += f"\n{caption}"
    return text
