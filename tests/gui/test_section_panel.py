"""The Midsagittal tab (issues 35 and 36): the replay's midsagittal view and the palatogram at the cursor, against
a flat palate over the block tongue (independent figures: the plane's cut of the tongue, the roof's height minus
a sensor's, the palatogram of that frame)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import demo_session, show_and_simulate  # noqa: E402
from tests.gui.test_palate_contact import ROOF_MM, flat_palate, simulate_with_palate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(240)]


@pytest.fixture(autouse=True)
def _in_the_model_frame(request):
    if "window" in request.fixturenames:
        window = request.getfixturevalue("window")
        window.state.set_run_settings(window.state.run_settings.replace(frame="model"))


def _tab(window, title: str) -> None:
    for k in range(window.tabs.count()):
        if window.tabs.tabText(k) == title:
            window.tabs.setCurrentIndex(k)
            return
    raise AssertionError(f"no tab {title}")


def test_the_midsagittal_tab_follows_the_cursor_with_the_palatogram(qtbot, window, tmp_path):
    from tonguevis.analysis.epg import palatogram
    from tonguevis.analysis.section import plane_section
    from tonguevis.render.drawing import head_points

    path = tmp_path / "flat.stl"
    flat_palate().save(path)
    session = simulate_with_palate(qtbot, window, path)
    _tab(window, "Midsagittal")
    panel = window.section_panel
    motion = session.motion
    i = int(np.argmax(motion.contact_area))
    assert motion.contact_area[i] > 0
    window.state.set_time(float(session.frames.times[i]))
    qtbot.waitUntil(lambda: panel.shown_frame == i, timeout=5000)
    view = panel.view
    # the tongue: the plane y = the rest nodes' median cut through the tongue as drawn at that frame
    y = float(np.median(motion.model.mesh.points[:, 1]))
    want = plane_section(head_points(session.frames, i), np.asarray(motion.model.surface_faces), y)
    assert len(view.segments) == len(want) > 10
    np.testing.assert_allclose(np.sort(view.segments.reshape(-1, 4), axis=0), np.sort(want.reshape(-1, 4), axis=0),
                               atol=1e-6)
    # the palate: a flat roof, nothing traced (a palate given as it is): all of it estimated, at its height
    assert len(view.palate) == 0 and len(view.palate_estimated) > 5
    np.testing.assert_allclose(view.palate_estimated[..., 1], 1e-3 * ROOF_MM, atol=1e-9)
    # each tongue sensor's constriction: under a flat roof, the roof's height minus the sensor's (as measured)
    k = motion.sensor_names.index("TT")
    tt = motion.targets[i, k] + (motion.jaw_offset[i] if motion.jaw_offset is not None else 0)
    line = next(text for text in view.lines if text.startswith("TT "))
    degree = ROOF_MM - 1e3 * tt[2]
    assert line.startswith(f"TT {degree:.1f} mm " if degree >= 0 else f"TT {-degree:.1f} mm above the palate")
    assert view.sensor_names and "TT" in view.sensor_names
    # the palatogram of that frame, lit where the tongue touches
    gram = palatogram(motion, [i])
    assert np.array_equal(panel.palatogram.contacts, gram.contacts[0]) and gram.contacts[0].any()
    assert panel.palatogram.lines()[0] == f"contact {gram.indices()['percent_contact'][0]:.0f} %"
    # the status line says where the tongue touches
    assert "touching " in window.frame_status.text()
    window.grab().save(str(tmp_path / "midsagittal.png"))
    # another frame: the tab follows
    j = max(0, i - 40)
    window.state.set_time(float(session.frames.times[j]))
    qtbot.waitUntil(lambda: panel.shown_frame == j, timeout=5000)
    assert view.lines[0].startswith(f"t = {session.frames.times[j]:.3f} s")


def test_without_a_palate_the_palatogram_says_why(qtbot, window):
    session = show_and_simulate(qtbot, window, demo_session())
    _tab(window, "Midsagittal")
    panel = window.section_panel
    window.state.set_time(float(session.frames.times[10]))
    qtbot.waitUntil(lambda: panel.shown_frame == 10, timeout=5000)
    if session.motion.palate is None:
        assert panel.palatogram.contacts is None and "without a palate" in panel.palatogram.note
    assert len(panel.view.segments) > 10
