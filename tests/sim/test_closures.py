"""A stop is a closure (issue 36): the tip pressed on the palate at each /t/ closure found, the dorsum at each /k/
closure; a rest the palate cuts through is passed over for the next still stretch."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from tonguevis.io import read_recording
from tonguevis.paths import DATA_DIR


@pytest.fixture(scope="module")
def ta():
    return read_recording(DATA_DIR / "spk1_ta.tsv")


def _closure_gaps(motion, frames, articulator="TT"):
    from tonguevis.sim.closures import constricting_region

    node = motion.sensor_nodes[motion.sensor_names.index(articulator)]
    region = constricting_region(motion.model, int(node), articulator)
    out = []
    for f in frames:
        points = motion.model.mesh.points + motion.displacement(f) + motion.jaw_offset[f]
        out.append(np.nanmin(motion.palate_at(f).clearance(points[region])[0]))
    return np.array(out)


def test_the_tip_is_pressed_on_the_palate_at_each_closure_and_stays_out_of_it(ta):
    from tonguevis.sim import simulate

    pressed = simulate(ta, modes=60, palate="generic")
    closures = pressed.metadata["contact"]["closures"]
    frames = closures["maximum_constriction_frames"]
    assert closures["articulator"] == "TT" and closures["closures"] == len(frames) >= 20  # five trains of five
    free = simulate(ta, modes=60, palate="generic", closures=False)
    assert "closures" not in free.metadata["contact"]
    with_pull, without = _closure_gaps(pressed, frames), _closure_gaps(free, frames)
    assert np.median(with_pull) < 1e-3 and np.median(with_pull) < 0.4 * np.median(without)
    assert pressed.penetration.max() < 5e-4  # pressed on it, kept out of it
    assert not pressed.metadata["recovered_frames"]
    assert pressed.metadata["plausibility"]["amplification"] < 2.0


def test_the_dorsum_is_pressed_on_the_palate_at_each_dorsal_closure_and_nothing_without_a_palate():
    """At a /k/ the dorsum about its coil is pressed onto the palate (the summary says "the dorsum touches");
    without a palate nothing is pressed."""
    from tonguevis.sim import simulate
    from tonguevis.sim.plausibility import contact_line

    ka = read_recording(DATA_DIR / "spk1_ka.tsv")
    pressed = simulate(ka, modes=40, palate="generic")
    closures = pressed.metadata["contact"]["closures"]
    frames = closures["maximum_constriction_frames"]
    assert closures["articulator"] == "TD" and closures["closures"] == len(frames) >= 20
    free = simulate(ka, modes=40, palate="generic", closures=False)
    with_pull, without = _closure_gaps(pressed, frames, "TD"), _closure_gaps(free, frames, "TD")
    assert np.median(with_pull) < 1e-3 and np.median(with_pull) < 0.4 * np.median(without)
    assert pressed.penetration.max() < 5e-4
    assert f"the dorsum touches at {pressed.metadata['contact']['closures_touching']} of" in contact_line(
        pressed.metadata)
    assert "contact" not in simulate(ka, modes=40).metadata


def test_a_rest_the_palate_cuts_is_passed_over_for_the_next_still_stretch(ta, monkeypatch, caplog):
    """The first rest candidate refused (the palate cutting through the tongue there): the next one is used, and
    its reason says why; every candidate refused: one error naming the file, the stretches tried and --rest."""
    import logging

    from tonguevis.errors import SimulationError
    from tonguevis.preprocess.rest import rest_candidates
    from tonguevis.sim import simulate
    from tonguevis.sim.palate_placement import PalateCutsTheRest

    placement = importlib.import_module("tonguevis.sim.palate_placement")
    simulate_module = importlib.import_module("tonguevis.sim.simulate")
    original = placement.contact_context
    candidates = rest_candidates(ta.on_uniform_grid())
    assert candidates[0].how == "detected" and len(candidates) >= 3
    first = candidates[0].interval

    def refuse_first(palate, prep, model, basis, recording):
        if prep.rest.interval == first:
            raise PalateCutsTheRest("the palate cuts through the tongue at the rest (test)", "x")
        return original(palate, prep, model, basis, recording)

    monkeypatch.setattr(simulate_module, "contact_context", refuse_first)
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        motion = simulate(ta, modes=30, palate="generic", closures=False)
    rest = motion.metadata["rest"]
    assert tuple(rest["interval"]) == candidates[1].interval and "cuts through the tongue" in rest["reason"]
    assert sum("cuts through the tongue" in r.getMessage() for r in caplog.records) == 1
    monkeypatch.setattr(simulate_module, "contact_context",
                        lambda *a: (_ for _ in ()).throw(PalateCutsTheRest("cut", "x")))
    with pytest.raises(SimulationError, match=r"spk1_ta.tsv: .*every still stretch tried .*--rest START END"):
        simulate(ta, modes=30, palate="generic")
    with pytest.raises(SimulationError, match=r"spk1_ta.tsv: cut; is it this speaker's palate"):
        simulate(ta, modes=30, palate="generic", rest=first)


def test_rest_candidates_are_the_rest_found_then_still_windows_apart():
    from tonguevis.preprocess.rest import STILLEST_WINDOW_S, choose_rest_interval, rest_candidates

    rec = read_recording(DATA_DIR / "spk2_ka.tsv").on_uniform_grid()
    candidates = rest_candidates(rec, count=5)
    assert candidates[0].interval == choose_rest_interval(rec).interval
    assert [c.how for c in candidates[1:]] == ["stillest window"] * 5
    spans = [c.interval for c in candidates]
    for i, (a0, a1) in enumerate(spans):
        for b0, b1 in spans[i + 1:]:
            assert b1 <= a0 - STILLEST_WINDOW_S + 1e-9 or b0 >= a1 + STILLEST_WINDOW_S - 1e-9


def test_a_model_that_runs_away_at_the_closures_is_simulated_without_their_pulls_and_says_so(caplog):
    """A coarse block (20 modes) cannot take the tip's pull onto a flat palate over it: rather than refuse the
    recording, simulate() drives it by the sensors and the contact alone, says so once, and the summary says so."""
    import logging

    from tests.gui.conftest import MODES, block_model, demo_session
    from tests.gui.test_palate_contact import flat_palate
    from tonguevis.sim import simulate
    from tonguevis.sim.plausibility import contact_line

    recording = demo_session().recording  # the app's first train of the demo /ta/
    tt = recording.sensors["TT"]
    palate = flat_palate(frame=None)
    centre = np.nanmean(tt, axis=0)
    palate.x, palate.y = palate.x + centre[0] + 0.02, palate.y + centre[1]
    palate.z = np.full_like(palate.z, np.nanmax(tt[:, 2]) + 2e-3)
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        motion = simulate(recording, block_model(), modes=MODES, frame="model", landmarks="rule", palate=palate)
    said = [r.getMessage() for r in caplog.records if "closures' pulls" in r.getMessage()]
    assert len(said) == 1
    c = motion.metadata["contact"]
    assert c["closures_dropped"] and "closures" not in c
    assert "the closures not pressed" in contact_line(motion.metadata)
    assert len(motion.metadata["recovered_frames"]) < 0.05 * motion.n_frames


def test_the_closures_are_said_where_the_tip_touches_not_where_the_tongue_touches_most(osn12_palate):
    """At a /t/ the sides and back of the tongue touch the palate too, over a larger area: on the real /ta/ 009
    "5 of 5 stop closures touch (back-left), the tip pressed on the palate there" was said while the tip was
    short of it.  How often and where are now the pressed region's own contact during each closure (its
    nucleus: at the maximum constriction alone the tip of 009 touched at 2 of 5 closures, within 3 frames at 4)."""
    from tests.conftest import shared_file
    from tonguevis.sim import simulate
    from tonguevis.sim.contact import TOUCH, node_areas
    from tonguevis.sim.palate_regions import palate_frame, place_of
    from tonguevis.sim.plausibility import contact_line

    recording = read_recording(shared_file("ema", "optispeech", "009_OSN12_Tah_withFb_natural_HR.tsv"))
    motion = simulate(recording, palate=str(osn12_palate))
    c = motion.metadata["contact"]
    closures = c["closures"]
    pressed = np.asarray(closures["nodes"])
    areas = node_areas(motion.model.mesh.points, np.asarray(motion.model.surface_faces))
    frame = palate_frame(motion.palate)
    places, everywhere = [], []
    windows = closures["closure_frames"]  # each closure's nucleus, where its pull holds
    assert len(windows) == closures["closures"]
    for (first, last), peak in zip(windows, closures["maximum_constriction_frames"]):
        assert first <= peak <= last
        where = ""
        for f in range(first, last + 1):  # where the pressed region first touches during the closure
            points = motion.model.mesh.points + motion.displacement(f) + motion.jaw_offset[f]
            gap = motion.palate_at(f).clearance(points)[0]
            on = np.isfinite(gap[pressed]) & (gap[pressed] < TOUCH)
            where = place_of(frame, points[pressed][on], areas[pressed][on])
            if where:
                break
        places.append(where)
        points = motion.model.mesh.points + motion.displacement(peak) + motion.jaw_offset[peak]
        gap = motion.palate_at(peak).clearance(points)[0]
        everywhere.append(bool(np.any(np.isfinite(gap) & (gap < TOUCH))))  # the whole tongue, at the peak alone
    named = [p for p in places if p]
    assert c["closures_touching"] == len(named)
    assert c["closures_where"] == (max(set(named), key=named.count) if named else "")
    assert 0 < len(named) and sum(everywhere) == len(everywhere)  # the tongue touches at every peak: not what is counted
    line = contact_line(motion.metadata)
    assert f"the tip touches at {len(named)} of {closures['closures']} stop closures" in line
