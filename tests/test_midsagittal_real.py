"""The replay's midsagittal picture and the 3D palate on a real /ta/ (OSN12 009) with the speaker's palate fitted
from the traces 002-004 (issues 35 and 36): the palate's section told apart where traced and where estimated, the
velum drawn lifted frame by frame (on the /ka/ 007), the status line saying where the tongue touches."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import shared_file


def _simulated(name: str, palate):
    from tonguevis.sim.settings import RunSettings
    from tonguevis.workflows.session import load_session
    from tonguevis.workflows.simulation import simulate_session

    path = shared_file("ema", "optispeech", f"{name}.tsv")
    return simulate_session(load_session(path), RunSettings(palate=str(palate)))


@pytest.fixture(scope="module")
def session(osn12_palate):
    return _simulated("009_OSN12_Tah_withFb_natural_HR", osn12_palate)


def _traced_at(surface, points: np.ndarray) -> np.ndarray:
    """Whether the grid cell nearest each (k, 3) point (head frame) was traced."""
    own = surface._to_own(points)
    ix = np.clip(np.searchsorted(surface.x, own[:, 0]), 0, len(surface.x) - 1)
    iy = np.clip(np.searchsorted(surface.y, own[:, 1]), 0, len(surface.y) - 1)
    return np.asarray(surface.traced)[iy, ix]


def test_the_palate_section_is_traced_in_front_and_estimated_behind(session):
    from tonguevis.render.midsagittal import MidsagittalSection

    section = MidsagittalSection(session)
    i = session.frames.frame_at(0.689)  # the first labelled /t/ closure
    picture = section.at(i)
    assert len(picture.traced) > 10 and len(picture.estimated) > 10
    surface = session.shown_palate.surface
    for segments, traced in ((picture.traced, True), (picture.estimated, False)):
        middle = segments.mean(axis=1)
        points = np.column_stack([middle[:, 0], np.full(len(middle), section.y), middle[:, 1]])
        assert np.mean(_traced_at(surface, points) == traced) > 0.8
    # the traced part is the front: its back end lies in front of the estimated part's
    assert picture.traced[..., 0].min() > picture.estimated[..., 0].min() + 0.01
    assert {"TT", "TB", "TD"} <= set(picture.sensors) and all(len(t) > 5 for t in picture.trails.values())
    assert [line.split()[0] for line in picture.lines()] == [c[0] for c in picture.constrictions]


def test_the_velum_is_drawn_lifted(osn12_palate):
    """On the /ka/ 007 (on the /ta/ 009 the broad estimated roof already clears the dorsum: no lift)."""
    from tonguevis.render.drawing import draw_frame

    session = _simulated("007_OSN12_Kah_withFb_natural_HR", osn12_palate)
    palate = session.shown_palate
    assert palate.lift is not None and palate.lift.max() > 0
    lifted = int(np.argmax(palate.lift))
    still = int(np.flatnonzero(palate.lift == 0)[0])
    up = draw_frame(session, lifted).context_shapes["palate"]
    down = draw_frame(session, still).context_shapes["palate"]
    rise = up[:, 2] - down[:, 2]
    # to the drawing's float32 (0.1 µm): since the estimated roof is raised broadly the velum lifts µm to 0.1 mm
    assert rise.max() == pytest.approx(palate.lift[lifted] * palate.share.max(), abs=1e-7)
    assert np.all(rise >= -1e-9) and np.array_equal(up[:, :2], down[:, :2])
    assert np.mean(rise > 1e-6) < 0.5  # only the velum rises, not the hard palate


def test_the_status_line_says_where_the_tongue_touches(session):
    from tonguevis.render.drawing import contact_at, contact_line

    # at the closures the tip touches: the status line says where
    closure = session.frames.frame_at(0.689)
    found = [contact_at(session, f)["place"] for f in range(closure - 3, closure + 4)]
    assert any(found)
    place = next(p for p in found if p)
    assert place.split("-")[0] in ("front", "middle", "back") and place.split("-")[1] in ("left", "centre", "right")
    assert "touching" in contact_line(session, closure - 3 + found.index(place), "head")
