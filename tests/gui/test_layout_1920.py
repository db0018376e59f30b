"""Layout at 1920 x 1080 (issue 27, item 14): whole texts in the 3D bar, one thin line for no sound,
the colour bar beside the tongue (not on its tip), a colour map whose low end stands off the background."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import demo_session, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(180)]


def test_the_3d_bar_combos_show_their_texts_whole_in_a_wide_window(qtbot, window):
    window.resize(1920, 1080)
    qtbot.wait(50)
    view = window.view3d
    for combo, longest in ((view.colour, "displacement magnitude"), (view.reference, "head frame (jaw moving")):
        assert any(longest in combo.itemText(i) for i in range(combo.count()))
        combo.setCurrentIndex(max(range(combo.count()), key=lambda i: len(combo.itemText(i))))
        assert combo.width() >= combo.sizeHint().width()  # the longest entry fits: nothing elided
    # and in a narrow window they give way instead of widening it past a laptop's screen
    assert view.colour.minimumSizeHint().width() < view.colour.sizeHint().width()


def test_no_sound_is_one_thin_line(qtbot, window):
    from tonguevis.gui.audio_panel import MIN_HEIGHT, SILENT_HEIGHT, SILENT_TEXT

    session = demo_session()
    silent = replace(session.recording, audio=None)
    from tonguevis.workflows.session import make_session

    show_and_simulate(qtbot, window, make_session(silent, session.path))
    audio = window.audio
    qtbot.waitUntil(lambda: audio.height() <= SILENT_HEIGHT, timeout=5000)
    assert audio.silent and audio.time_axes == []
    assert [t.get_text() for t in audio.figure.texts] == [SILENT_TEXT]
    assert audio.height() <= SILENT_HEIGHT < 0.03 * window.height()  # was a fifth of the window
    show_and_simulate(qtbot, window, demo_session())  # with sound: the waveform and spectrogram again
    assert not audio.silent and audio.minimumHeight() >= MIN_HEIGHT and len(audio.time_axes) == 2


def test_the_colour_maps_low_end_stands_off_the_background():
    import pyvista as pv

    from tonguevis.render.scene import BACKGROUND, colour_map, contrast_ratio

    lut = pv.LookupTable(cmap=colour_map(), n_values=256)
    lut.scalar_range = (0.0, 1.0)
    assert contrast_ratio(lut.map_value(0.0)[:3], BACKGROUND) > 1.5  # plasma's own low end: 1.14
    assert contrast_ratio("#0d0887", BACKGROUND) < 1.2


@pytest.mark.parametrize("size", [(1068, 760), (900, 700), (1500, 700)])
def test_the_colour_bar_sits_beside_the_tongue_not_on_its_tip(size):
    """The 3D views' widget at 1920 x 1080 (1068 x 760), narrower and wider: every surface node
    of the tongue, as the main view draws it, lies left of the colour bar."""
    import pyvista as pv

    from tonguevis.render.scene import TongueScene
    from tonguevis.sim import TongueModel

    model = TongueModel.default()
    plotter = pv.Plotter(shape="1|3", off_screen=True, window_size=size)
    try:
        scene = TongueScene(plotter)
        scene.build(model.mesh.points, model.surface_faces, 5, clim={"displacement": (0.0, 7.0)},
                    titles={"displacement": "displacement\n(mm)"})
        scene.set_mode("displacement")
        plotter.render()
        renderer = plotter.renderers[0]
        xs = []
        for point in model.mesh.points[np.unique(model.surface_faces)]:
            renderer.SetWorldPoint(*point, 1.0)
            renderer.WorldToDisplay()
            xs.append(renderer.GetDisplayPoint()[0])
        bar_left = scene.scalar_bar.GetPositionCoordinate().GetComputedDisplayValue(renderer)[0]
        left = renderer.GetOrigin()[0]
        assert max(xs) < bar_left - 0.03 * renderer.GetSize()[0]  # a margin, the numbers right of the bar
        assert min(xs) > left  # and the tongue's back still in the view
    finally:
        plotter.close()
