"""The 3D scene lit on the CPU at the vertices and drawn unlit (:mod:`tonguevis.render.shading`):
the same light as VTK's, following each view's camera, the frame's colours and the colouring;
closed shells drawn without their back faces and lit from outside."""

from __future__ import annotations

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")

from tonguevis.render.scene import LIGHTS, MAIN, TONGUE_COLOUR, TONGUE_MATERIAL, TOP, TongueScene, set_lights  # noqa: E402
from tonguevis.render.shading import shade  # noqa: E402
from tonguevis.render.surface_geometry import is_closed, outward_normals  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]

SIZE = (320, 320)


def _render(plotter) -> np.ndarray:
    plotter.render()
    return np.asarray(plotter.screenshot(return_img=True), dtype=float)[..., :3]


def _sphere() -> pv.PolyData:
    sphere = pv.Sphere(radius=0.02, theta_resolution=90, phi_resolution=90)
    return sphere.compute_normals(point_normals=True, cell_normals=False, auto_orient_normals=True)


def test_vertex_lighting_matches_vtk_lighting_the_same_surface():
    """A finely tessellated sphere (tongue material, coloured by a gradient) lit by VTK with the
    app's lights, and the same sphere drawn unlit in the colours :func:`shade` computes: the
    pictures agree to a few grey levels (only the interpolation differs: VTK lights each
    pixel, shade each vertex)."""
    sphere = _sphere()
    base = np.column_stack([np.linspace(0.3, 1.0, sphere.n_points), np.full(sphere.n_points, 0.45),
                            np.linspace(0.9, 0.2, sphere.n_points)])
    pictures = []
    for cpu in (False, True):
        plotter = pv.Plotter(off_screen=True, window_size=SIZE)
        plotter.set_background("black")
        set_lights(plotter.renderer)
        mesh = sphere.copy()
        if cpu:
            camera = plotter.camera
            plotter.camera_position = [(0.05, -0.09, 0.05), (0, 0, 0), (0, 0, 1)]
            view = np.array([[camera.GetViewTransformMatrix().GetElement(r, c) for c in range(4)] for r in range(4)])
            mesh.point_data["rgb"] = shade(base, mesh.point_data["Normals"], mesh.points, view, LIGHTS,
                                           **TONGUE_MATERIAL)
            plotter.add_mesh(mesh, scalars="rgb", rgb=True, lighting=False)
        else:
            mesh.point_data["rgb"] = np.rint(255 * base).astype(np.uint8)
            actor = plotter.add_mesh(mesh, scalars="rgb", rgb=True, smooth_shading=True, **TONGUE_MATERIAL)
            actor.prop.interpolation = "gouraud"
            plotter.camera_position = [(0.05, -0.09, 0.05), (0, 0, 0), (0, 0, 1)]
        pictures.append(_render(plotter))
        plotter.close()
    vtk_lit, cpu_lit = pictures
    on_sphere = vtk_lit.sum(axis=-1) > 0
    assert 0.2 < on_sphere.mean() < 0.9
    difference = np.abs(vtk_lit - cpu_lit)[on_sphere]
    assert difference.mean() < 3.0, difference.mean()
    # The light is not flat: the sphere has a bright and a dark side, in both pictures alike.
    brightness = cpu_lit.sum(axis=-1)[on_sphere]
    assert brightness.max() - brightness.min() > 200


def _random_surface(rng, n: int):
    """(n, 3) random unit normals, points within ~1 cm of the origin, and base colours."""
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return normals, rng.normal(size=(n, 3)) * 0.01, rng.random((n, 3))


def test_shade_against_a_per_vertex_loop():
    """The vectorised lighting equals the equation written out for one vertex at a time."""
    n = 50
    normals, points, base = _random_surface(np.random.default_rng(3), n)
    angle = 0.4
    view = np.eye(4)
    view[:3, :3] = [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]]
    view[2, 3] = -0.2
    material = dict(ambient=0.1, diffuse=0.9, specular=0.3, specular_power=15.0)
    for parallel in (False, True):
        for two_sided in (False, True):
            fast = shade(base, normals, points, view, LIGHTS, parallel=parallel, two_sided=two_sided, **material)
            for i in range(n):
                nv = view[:3, :3] @ normals[i]
                eye = np.array([0, 0, 1.0]) if parallel else -(view[:3, :3] @ points[i] + view[:3, 3])
                eye = eye / np.linalg.norm(eye)
                if two_sided and nv @ eye < 0:
                    nv = -nv
                colour = material["ambient"] * base[i]
                for direction, intensity in LIGHTS:
                    towards = np.array((0, 0, 1.0) if direction is None else direction, dtype=float)
                    towards /= np.linalg.norm(towards)
                    cos = nv @ towards
                    colour = colour + material["diffuse"] * intensity * max(cos, 0.0) * base[i]
                    if cos > 0:
                        reflected = 2 * cos * nv - towards
                        colour = colour + material["specular"] * intensity * max(reflected @ eye, 0.0) ** 15.0
                expected = np.clip(np.rint(255 * colour), 0, 255)
                np.testing.assert_array_equal(fast[i], expected)


def test_shade_many_views_at_once_equals_one_at_a_time():
    """Lighting a stack of views (perspective and orthographic mixed) in one pass gives each
    view the colours it gets alone."""
    n = 200
    normals, points, base = _random_surface(np.random.default_rng(5), n)
    views = []
    for angle, distance in ((0.4, -0.2), (1.3, -0.3), (-2.0, -0.25)):
        view = np.eye(4)
        view[:3, :3] = [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]]
        view[2, 3] = distance
        views.append(view)
    parallel = [False, True, False]
    material = dict(ambient=0.1, diffuse=0.9, specular=0.3, specular_power=15.0)
    for two_sided in (False, True):
        together = shade(base, normals, points, np.array(views), LIGHTS, parallel=parallel,
                         two_sided=two_sided, **material)
        assert together.shape == (3, n, 3)
        for k, view in enumerate(views):
            alone = shade(base, normals, points, view, LIGHTS, parallel=parallel[k], two_sided=two_sided, **material)
            np.testing.assert_array_equal(together[k], alone)
        assert np.abs(together[0].astype(int) - together[2]).max() > 50  # the views differ


@pytest.fixture
def plotters():
    """Off-screen plotters closed after the test, whatever it asserts (an X connection left to
    the interpreter's exit ends the process badly under Xvfb)."""
    made = []
    yield made
    for plotter in made:
        plotter.close()


def _draw(plotter) -> None:
    plotter.render_window.Render()  # Plotter.render() does nothing before the plotter is shown


def _scene(plotters, context=True):
    plotter = pv.Plotter(off_screen=True, shape="1|3", splitting_position=0.72, window_size=(640, 400))
    plotters.append(plotter)
    scene = TongueScene(plotter)
    tongue = pv.Sphere(radius=0.02, theta_resolution=24, phi_resolution=24)
    faces = np.asarray(tongue.faces).reshape(-1, 4)[:, 1:]
    shells = {"jaw": pv.Sphere(radius=0.035, center=(0, 0, -0.01)).triangulate()} if context else {}
    scene.build(np.asarray(tongue.points), faces, context=shells,
                clim={"displacement": (0.0, 1.0), "contact": (0.0, 10.0)})
    return plotter, scene, np.asarray(tongue.points)


def _view_rgb(scene, index):
    return np.array(scene._tongue_views[index].point_data["rgb"])[scene.shaded_nodes].astype(int)


def test_the_tongue_is_lit_for_each_views_camera_and_follows_its_frame_and_colouring(plotters):
    plotter, scene, points = _scene(plotters)
    scene.set_mode("displacement")
    values = np.linspace(0.0, 1.0, len(points))
    scene.update(points, values, render=False)
    _draw(plotter)
    main, top = _view_rgb(scene, MAIN), _view_rgb(scene, TOP)
    assert not np.array_equal(main, top)  # the lights follow each view's camera

    # The camera turns: the main view's colours are lit again; the top view's stay.
    plotter.subplot(MAIN)
    plotter.camera.azimuth = 90
    _draw(plotter)
    assert np.abs(_view_rgb(scene, MAIN) - main).max() > 30
    np.testing.assert_array_equal(_view_rgb(scene, TOP), top)

    # Values written straight into the surface after update (as the compare view colours A by the
    # distance to B) are what the next render shows.
    turned = _view_rgb(scene, MAIN)
    scene.surface.point_data["value"][:] = values[::-1]
    _draw(plotter)
    assert np.abs(_view_rgb(scene, MAIN) - turned).max() > 30
    expected = scene.lookup_table.map_value(float(values[::-1][scene.shaded_nodes[0]]))
    np.testing.assert_allclose(scene.tongue_colours()[0], expected[:3], atol=1 / 255 + 1e-9)

    # Plain: one colour for every node, lit (brightness varies, hue does not).
    scene.set_mode("plain")
    _draw(plotter)
    assert scene.lookup_table is None
    colours = scene.tongue_colours()
    np.testing.assert_allclose(colours, np.broadcast_to(pv.Color(TONGUE_COLOUR).float_rgb, colours.shape))
    lit = _view_rgb(scene, MAIN)
    assert lit.sum(axis=1).max() - lit.sum(axis=1).min() > 100


def test_closed_shells_are_culled_and_lit_from_outside(plotters):
    """A closed shell is drawn without its back faces and lit by its outward normals even when its
    triangles are wound inwards; an open sheet is neither culled nor one-sided."""
    sphere = pv.Sphere(radius=0.03).triangulate()
    faces = np.asarray(sphere.faces).reshape(-1, 4)[:, 1:]
    points = np.asarray(sphere.points)
    assert is_closed(faces) and is_closed(faces[:, ::-1])
    radial = points / np.linalg.norm(points, axis=1, keepdims=True)
    for winding in (faces, faces[:, ::-1]):
        normals = outward_normals(points, winding)
        assert np.all(np.einsum("ij,ij->i", normals, radial) > 0.9)
    sheet = pv.Plane(i_resolution=4, j_resolution=4).triangulate()
    assert not is_closed(np.asarray(sheet.faces).reshape(-1, 4)[:, 1:])

    plotter, scene, _ = _scene(plotters, context=True)
    _draw(plotter)
    shells = scene.context_actors
    assert shells and all(actor.prop.GetBackfaceCulling() for actor in shells)
    assert all(not actor.prop.lighting for actor in shells + scene.surface_actors)
    # The shell's side towards the main camera is lit, so not black.
    rgb = np.array(scene._context_views[MAIN]["jaw"].point_data["rgb"]).astype(int)
    assert rgb.max() > 100


def test_the_closed_tongue_skips_its_far_side_whichever_way_it_is_wound(plotters):
    """The opaque tongue is drawn without its inside (back faces, or front faces for triangles wound
    inwards) and lit from outside: both windings give the same picture as drawing every face."""
    pictures = []
    for winding in ("outwards", "inwards", "all faces"):
        plotter = pv.Plotter(off_screen=True, shape="1|3", splitting_position=0.72, window_size=(480, 300))
        plotters.append(plotter)
        scene = TongueScene(plotter)
        tongue = pv.Sphere(radius=0.02, theta_resolution=24, phi_resolution=24)
        faces = np.asarray(tongue.faces).reshape(-1, 4)[:, 1:]
        scene.build(np.asarray(tongue.points), faces[:, ::-1] if winding == "inwards" else faces,
                    clim={"displacement": (0.0, 1.0)})
        actor = scene.surface_actors[MAIN]
        culled = (actor.prop.GetBackfaceCulling(), actor.prop.GetFrontfaceCulling())
        assert culled == {"outwards": (True, False), "inwards": (False, True), "all faces": (True, False)}[winding]
        if winding == "all faces":
            for each in scene.surface_actors:
                each.prop.SetBackfaceCulling(False)
        pictures.append(_render(plotter))
    differs = np.abs(pictures[0] - pictures[2]).max(axis=2)
    # the same picture but for a few silhouette pixels where the far side ties in depth (a camera-dependent rounding)
    assert (differs > 0).mean() < 1e-3 and differs.max() <= 8, ((differs > 0).sum(), differs.max())
    assert np.abs(pictures[1] - pictures[2]).mean() < 0.5  # same light from outside (rounding only)
    assert (pictures[0].sum(axis=-1) > 150).mean() > 0.05  # a lit tongue, not a dark one


def test_contact_colours_say_inside_and_no_palate_above_in_their_own_colours(plotters):
    """Distance to the palate: a node inside the palate (below the range) is magenta, one with no
    palate above (NaN) neutral grey, the others on the red-to-blue map; the lit colours start
    from these (the lookup table's special colours are brought up to date before mapping)."""
    from tonguevis.render.scene import INSIDE_COLOUR, NO_PALATE_COLOUR

    plotter, scene, points = _scene(plotters, context=False)
    scene.set_mode("contact")
    values = np.full(len(points), 5.0, dtype=np.float32)
    nodes = scene.shaded_nodes
    values[nodes[0]], values[nodes[1]], values[nodes[2]] = np.nan, -1.0, 0.1
    scene.update(points, values, render=False)
    colours = scene.tongue_colours()
    np.testing.assert_allclose(colours[0], pv.Color(NO_PALATE_COLOUR).float_rgb, atol=1 / 255)
    np.testing.assert_allclose(colours[1], pv.Color(INSIDE_COLOUR).float_rgb, atol=1 / 255)
    red = colours[2]
    assert red[0] > 0.6 and red[2] < 0.3  # touching: red
    np.testing.assert_allclose(colours[3], np.array(scene.lookup_table.map_value(5.0)[:3]), atol=1 / 255)
