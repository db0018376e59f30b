"""The live window's views: a live session's frames drawn in the 3D view, the midsagittal view and the palatogram.

The 3D view is the patient's: the simulated tongue surface (lit on the CPU, drawn unlit), the
sensors, the palate and the jaw as the simulator placed them on the rest, the targets as spheres
coloured by their accuracy in a layer over the scene (a target inside the tongue stays in sight),
a replay target's ghost.  The midsagittal view (the tongue's section in the plane of its middle)
and the palatogram are the replay app's widgets (:mod:`tonguevis.gui.midsagittal_view`,
:mod:`tonguevis.gui.palatogram_view`).  :meth:`LiveViews.draw` draws one
:class:`~tonguevis.live.session.LiveUpdate`; everything it draws comes from the update and the session.
"""

from __future__ import annotations

import time

import numpy as np

from tonguevis.gui.midsagittal_view import BACKGROUND, GHOST_COLOUR, SENSOR_COLOUR, TONGUE_COLOUR, MidsagittalView
from tonguevis.gui.palatogram_view import PalatogramView
from tonguevis.live.targets import accuracy_colour

#: The live 3D view renders at this share of its pixels in each direction and is drawn scaled up:
#: under software OpenGL the render is most of the latency and goes with the pixels (0.8: 36 % fewer).
LIVE_RENDER_SCALE = 0.8


class LiveViews:
    """The 3D view (``plotter``, its widget ``plotter.interactor`` made in ``parent``), the ``midsagittal``
    view and the ``palatogram`` (made in ``views_parent``) of the live window, drawn from a live session."""

    def __init__(self, parent, views_parent):
        from tonguevis.gui.view3d import make_plotter

        from tonguevis.render.scene import set_lights

        self.plotter = make_plotter(parent, multi_samples=0, auto_update=False)
        if hasattr(self.plotter, "set_render_scale"):  # the picture drawn from fewer pixels: less latency
            self.plotter.set_render_scale(LIVE_RENDER_SCALE)
        self.plotter.set_background(BACKGROUND)
        renderer = self.plotter.renderer
        # As the app's scene (tonguevis.render.scene): under software OpenGL, VTK's order-independent
        # transparency costs extra full-screen passes (it more than doubled this view's render), the
        # frustum culler re-runs every moving actor's pipeline, and each light is paid per pixel.
        renderer.SetUseOIT(False)
        renderer.GetCullers().RemoveAllItems()
        set_lights(renderer)
        # The targets in a layer over the scene, with the same camera: a target inside or behind the tongue
        # (where the tip is to go) stays in sight, as the patient must see it.
        import vtk

        self.overlay = vtk.vtkRenderer()
        self.overlay.SetLayer(1)
        self.overlay.InteractiveOff()
        self.overlay.SetActiveCamera(renderer.GetActiveCamera())
        self.overlay.SetUseOIT(False)
        self.overlay.GetCullers().RemoveAllItems()
        set_lights(self.overlay)
        self.plotter.ren_win.SetNumberOfLayers(2)
        self.plotter.ren_win.AddRenderer(self.overlay)
        self.midsagittal = MidsagittalView(views_parent)
        self.palatogram = PalatogramView(views_parent)
        self.session = None
        self.surface_mesh = None
        self.sensor_mesh = None
        self.target_actors: list = []
        self.ghost_mesh = None
        self.shown_palate = None  # the palate as placed on the rest (a ShownPalate), once a rest is taken
        self.palate_mesh, self._palate_faces, self._lift_drawn = None, None, 0.0  # drawn, its velum lifted so
        self.jaw_mesh = None
        self._jaw_rest = None
        self._scene_sim = None  # the simulator whose tongue, palate and jaw the scene shows

    def forget(self) -> None:
        """Nothing drawn: the next frame builds the scene again."""
        self.forget_tongue()
        if self.sensor_mesh is not None:
            self.plotter.remove_actor("sensors")
            self.sensor_mesh = None
        self._draw_ghost(None)
        self.forget_targets()

    def forget_targets(self) -> None:
        """No target drawn (the targets changed: the next frame draws them anew)."""
        for actor in self.target_actors:
            self.overlay.RemoveActor(actor)
        self.target_actors = []

    def forget_tongue(self) -> None:
        """The tongue, palate and jaw of the last rest gone (a new rest places them again)."""
        for name in ("tongue", "palate", "jaw"):
            self.plotter.remove_actor(name)
        self.surface_mesh = self.jaw_mesh = self.shown_palate = self._scene_sim = self.palate_mesh = None

    def draw(self, update, session) -> dict:
        """Draw ``update`` (a :class:`~tonguevis.live.session.LiveUpdate` of ``session``) in the three views;
        returns the stages' times (ms: "scene", "render", "submit", "paint", "targets", "reconstruct")."""
        import pyvista as pv

        t0 = time.perf_counter()
        self.session = session
        sim = session.simulator
        surface = update.surface
        if surface is not None:
            if sim is not self._scene_sim:
                self.forget_tongue()
            if self.surface_mesh is None:
                self._show_tongue(sim, surface)
            else:
                self.surface_mesh.points[:] = surface
                self.surface_mesh.point_data["colours"][:] = self._shaded(surface)
                self.surface_mesh.Modified()
            if self.jaw_mesh is not None:
                self.jaw_mesh.points[:] = self._jaw_rest + np.asarray(update.step.jaw_offset, dtype=np.float32)
                self.jaw_mesh.Modified()
            self._lift_velum(update.velum_lift)
        drawn_sensors = update.sensors
        if self.sensor_mesh is None:
            self.sensor_mesh = pv.PolyData(np.nan_to_num(np.array(drawn_sensors, dtype=np.float32)))
            self.plotter.add_mesh(self.sensor_mesh, color=SENSOR_COLOUR, point_size=14, render_points_as_spheres=True,
                                  name="sensors")
            if surface is None:
                self.plotter.reset_camera()
        elif len(self.sensor_mesh.points) == len(drawn_sensors):
            self.sensor_mesh.points[:] = np.nan_to_num(drawn_sensors)
            self.sensor_mesh.Modified()
        else:
            self.plotter.remove_actor("sensors")
            self.sensor_mesh = None
        t1 = time.perf_counter()
        self._draw_targets(update)
        t2 = time.perf_counter()
        # VTK's render returns once the frame is submitted; Mesa rasterises it on its own threads while
        # the midsagittal section is computed here, then the paint reads it back and shows it.
        self.plotter.render()
        t3 = time.perf_counter()
        if surface is not None:
            from tonguevis.analysis.section import plane_section

            self.midsagittal.segments = plane_section(surface, sim.surface_faces, self._mid_y)
            self.midsagittal.sensors = np.asarray(drawn_sensors)[:, [0, 2]]
        self.midsagittal.update()  # painted at the next turn of the event loop, after the 3D view
        t4 = time.perf_counter()
        self._paint()
        t5 = time.perf_counter()
        contacts = session.palatogram(update)  # after the paint: not in the drawn frame's latency
        if contacts is not None:
            self.palatogram.show_contacts(contacts, f"t = {update.time_s:.2f} s")
        step = update.step
        return {"reconstruct": 1e3 * (step.timings["reconstruct"] if step is not None else 0.0),
                "scene": 1e3 * (t2 - t0 + t4 - t3), "render": 1e3 * (t3 - t2 + t5 - t4),
                "submit": 1e3 * (t3 - t2), "paint": 1e3 * (t5 - t4), "targets": 1e3 * (t2 - t1)}

    def _show_tongue(self, sim, surface: np.ndarray) -> None:
        """The tongue of a new rest: its mesh, the camera on it, the midsagittal bounds, the palate and the jaw."""
        import pyvista as pv

        from tonguevis.render.surface_geometry import VertexNormals, outward_normals

        faces = np.hstack([np.full((len(sim.surface_faces), 1), 3), sim.surface_faces]).ravel()
        # Lit on the CPU at the vertices and drawn unlit, its hidden back faces culled (as the app's
        # scene: VTK's per-pixel lighting in software costs more than the 736 vertices' shading).
        self._normals = VertexNormals(sim.surface_faces, len(surface))
        self._normal_sign = 1.0 if np.allclose(outward_normals(sim.rest_surface, sim.surface_faces),
                                               self._normals(sim.rest_surface)) else -1.0
        self.surface_mesh = pv.PolyData(np.array(surface, dtype=np.float32), faces)
        self.surface_mesh.point_data["colours"] = self._shaded(surface)
        self.plotter.add_mesh(self.surface_mesh, scalars="colours", rgb=True, name="tongue",
                              lighting=False, culling="back" if self._normal_sign > 0 else "front")
        rest = sim.rest_surface
        centre = rest.mean(axis=0)
        # The app's main view: from the front right and above (x anterior, y left, z up), the tongue fitted.
        self.plotter.camera_position = [tuple(centre + np.array([0.55, -1.0, 0.55])), tuple(centre), (0, 0, 1)]
        self.midsagittal.set_bounds(rest[:, [0, 2]], margin=0.35)
        self._mid_y = float(np.median(rest[:, 1]))
        self._scene_sim = sim
        self._show_context(sim)
        lo, hi = rest.min(axis=0), rest.max(axis=0)
        if self.shown_palate is not None:  # and the palate over it: the contact is what a clinician looks at
            over = np.asarray(self.shown_palate.points, dtype=np.float64)
            over = over[np.all((over[:, :2] >= lo[:2]) & (over[:, :2] <= hi[:2]), axis=1)]
            if len(over):
                hi = hi.copy()
                hi[2] = max(hi[2], float(over[:, 2].max()))
        self.plotter.renderer.ResetCamera(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])  # the tongue (and palate) alone
        self.plotter.camera.zoom(1.4 if self.shown_palate is None else 1.2)
        self.surface_mesh.point_data["colours"][:] = self._shaded(surface)

    def _show_context(self, sim) -> None:
        """Once the rest is taken: the palate as the simulator placed it (3D and the midsagittal section, traced
        and estimated told apart), the jaw."""
        import pyvista as pv

        from tonguevis.render.scene import context_surfaces

        for name in ("palate", "jaw"):
            self.plotter.remove_actor(name)
        jaw = context_surfaces(None, sim.model).get("jaw")
        if jaw is not None:
            self.jaw_mesh = jaw
            self._jaw_rest = np.array(jaw.points, dtype=np.float32)
            self.plotter.add_mesh(jaw, color="#c8c8c8", opacity=0.25, name="jaw", lighting=True,
                                  culling="back")
        self.shown_palate = None
        if sim.palate is None:
            return
        from tonguevis.render.drawing import generic_shown, palate_label, speaker_palate
        from tonguevis.render.midsagittal import palate_sections
        from tonguevis.render.surface_geometry import hidden_side

        if sim.palate.metadata.get("generic"):
            shown = generic_shown(True, sim.model)
        else:
            # lift=[0]: the share of a lift each drawn point takes, for the velum the dorsum lifts frame by frame
            shown = speaker_palate(sim.palate, palate_label(self.session.settings.palate), lift=np.zeros(1))
        self.shown_palate = shown
        self.palate_mesh, self._palate_faces, self._lift_drawn = None, None, 0.0
        if shown is not None:
            from tonguevis.render.midsagittal import split_palate

            faces = np.hstack([np.full((len(shown.faces), 1), 3), shown.faces]).ravel()
            # a copy: VTK would share the array, and each lift drawn would move the palate at rest with it
            self.palate_mesh = pv.PolyData(np.array(shown.points, dtype=np.float32), faces)
            # an open sheet, seen from both sides (as the replay's scene draws it): culled, it vanished from above
            self.plotter.add_mesh(self.palate_mesh, color="#8fc1e3", opacity=0.3, name="palate",
                                  culling=hidden_side(self.palate_mesh.points, shown.faces))
            self._palate_faces = split_palate(shown)
            self.midsagittal.palate, self.midsagittal.palate_estimated = palate_sections(
                shown, self._mid_y, faces=self._palate_faces)
        if self.session.epg is None:
            self.palatogram.show_contacts(None, "no electrode layout on this palate")

    def _lift_velum(self, lift: float) -> None:
        """The palate drawn (3D and its midsagittal section) with its velum lifted ``lift`` m, when that changed."""
        shown = self.shown_palate
        if shown is None or shown.share is None or self.palate_mesh is None or abs(lift - self._lift_drawn) < 1e-5:
            return
        from tonguevis.render.midsagittal import palate_sections

        shown.lift[0] = lift  # its one frame: now
        drawn = shown.points_at(0)
        self.palate_mesh.points[:] = drawn
        self.palate_mesh.Modified()
        self.midsagittal.palate, self.midsagittal.palate_estimated = palate_sections(
            shown, self._mid_y, faces=self._palate_faces, drawn=drawn)
        self._lift_drawn = lift

    def _shaded(self, surface: np.ndarray) -> np.ndarray:
        """(k, 3) uint8 colours of the tongue's vertices lit by the view's lights for the camera now."""
        from matplotlib.colors import to_rgb

        from tonguevis.render.scene import LIGHTS, TONGUE_MATERIAL
        from tonguevis.render.shading import shade

        camera = self.plotter.renderer.GetActiveCamera()
        view = np.array([[camera.GetViewTransformMatrix().GetElement(i, j) for j in range(4)] for i in range(4)])
        normals = self._normal_sign * self._normals(surface)
        return shade(np.array(to_rgb(TONGUE_COLOUR)), normals, surface, view, LIGHTS, **TONGUE_MATERIAL)

    def render(self) -> None:
        """Render the 3D view now and paint it (synchronously: the frame is on screen when this returns)."""
        self.plotter.render()
        self._paint()

    def _paint(self) -> None:
        """Paint the 3D view rendered last, now."""
        # Painted now, not at the next turn of the event loop: the image views read the frame back and
        # draw it, the QOpenGLWidget composes it.  (Not QApplication.processEvents(): called at this rate,
        # PySide6 6.12's wrapper drops a reference to None each time until Python aborts.)
        self.plotter.interactor.repaint()

    def _draw_targets(self, update) -> None:
        """The targets where the session placed them, coloured by their accuracy (3D overlay and midsagittal)."""
        import pyvista as pv

        targets = self.session.targets
        while len(self.target_actors) > len(targets):
            self.overlay.RemoveActor(self.target_actors.pop())
        shown = []
        for j, (target, (centre, acc)) in enumerate(zip(targets, update.targets)):
            rgb = tuple(float(c) for c in accuracy_colour(acc))
            if j >= len(self.target_actors):
                sphere = pv.Sphere(radius=target.radius, theta_resolution=24, phi_resolution=16)
                actor = pv.Actor(mapper=pv.DataSetMapper(sphere))
                actor.prop.opacity = max(target.opacity, 0.35)
                actor.prop.specular = 0.3
                self.overlay.AddActor(actor)
                self.target_actors.append(actor)
            actor = self.target_actors[j]
            actor.prop.color = rgb
            finite = np.all(np.isfinite(centre))
            actor.SetVisibility(bool(finite))
            if finite:
                actor.SetPosition(*centre)
            shown.append((centre[0], centre[2], target.radius, rgb))
        self.midsagittal.targets = shown
        self._draw_ghost(update.ghost)

    def _draw_ghost(self, ghost) -> None:
        """The replay target's template sensors (the ghost tongue), translucent, joined tip to back."""
        import pyvista as pv

        if not ghost:
            if self.ghost_mesh is not None:
                self.plotter.remove_actor("ghost")
                self.ghost_mesh = None
            self.midsagittal.ghost = np.zeros((0, 2))
            return
        # The midline sensors joined tip to back (the ghost's profile); the others are not drawn.
        order = [n for n in ("TT", "TB", "TM", "TD", "TBK") if n in ghost] or list(ghost)
        points = np.nan_to_num(np.array([ghost[n] for n in order], dtype=np.float32))
        if self.ghost_mesh is None or len(self.ghost_mesh.points) != len(points):
            self.ghost_mesh = pv.lines_from_points(points) if len(points) > 1 else pv.PolyData(points)
            self.plotter.add_mesh(self.ghost_mesh, color=GHOST_COLOUR, opacity=0.6, line_width=4, point_size=12,
                                  render_points_as_spheres=True, render_lines_as_tubes=True, name="ghost")
        else:
            self.ghost_mesh.points[:] = points
            self.ghost_mesh.Modified()
        self.midsagittal.ghost = points[:, [0, 2]]
