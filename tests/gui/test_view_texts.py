"""The 3D views' own texts (captions, the small views' labels, the colour bar's title) stay inside their
views at any width (issue 37, item 2): they wrap to it."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pyvista")

pytestmark = [pytest.mark.gui, pytest.mark.timeout(240)]


@pytest.mark.parametrize("size", [(540, 620), (1068, 760)])
def test_the_views_texts_stay_inside_their_views(size):
    """The 3D views at 1280 pixels with a recording compared beside (540 wide) and at 1920 (1068): the
    main caption ("head frame: tongue and jaw move with the jaw, palate fixed"), the small views' labels
    and the colour bar's title ("displacement") were cut at the views' edges; they wrap instead."""
    import pyvista as pv
    import vtk

    from tonguevis.render.scene import COLOUR_BAR, LATERAL, MAIN, TongueScene, scene_titles
    from tonguevis.sim import TongueModel

    model = TongueModel.default()
    plotter = pv.Plotter(shape="1|3", off_screen=True, window_size=size)
    try:
        scene = TongueScene(plotter)
        scene.build(model.mesh.points, model.surface_faces, 5, clim={"displacement": (0.0, 7.0)},
                    titles=scene_titles())
        scene.set_mode("displacement")
        scene.update(model.mesh.points, None, np.zeros((5, 3)), np.zeros((5, 3)),
                     "t = 2.409 s   frame 240/1092\nhead frame: tongue and jaw move with the jaw, palate fixed")
        scene.set_view_labels(" · head frame")
        plotter.render()
        for caption, index in ((scene.time_text, MAIN), (scene.view_labels[LATERAL], LATERAL)):
            renderer = plotter.renderers[index]
            box = [0.0] * 4
            caption.actor.GetBoundingBox(renderer, box)
            assert box[1] <= renderer.GetSize()[0], (caption.actor.GetInput(), box, renderer.GetSize())
        assert "palate fixed" in scene.time_text.GetText(2)  # the text as set, whole
        renderer = plotter.renderers[MAIN]
        title = scene.scalar_bar.GetTitle()
        box = [0] * 4
        vtk.vtkTextRenderer.GetInstance().GetBoundingBox(scene.scalar_bar.GetTitleTextProperty(), title, box, 72)
        left = COLOUR_BAR["position_x"] * renderer.GetSize()[0]  # VTK centres the title on the bar's left edge
        assert left + (box[1] - box[0]) / 2 <= renderer.GetSize()[0], (title, box, renderer.GetSize())
        assert title.replace("-\n", "").replace("\n", " ").startswith("displacement")
    finally:
        plotter.close()
