"""A sensor within 1 mm under the palate is held to it (the coil between tongue and palate), and the
tongue then touches the palate there: contact area above zero in every such frame (issue 23 item 4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tonguevis.palate import PalateSurface
from tonguevis.sim.simulate import TOUCH_REACH, held_to_palate

OPTI = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "ema" / "optispeech"


def _tilted_palate(height: float = 0.02, slope: float = 0.2) -> PalateSurface:
    x = np.linspace(-0.05, 0.05, 101)
    y = np.linspace(-0.03, 0.03, 61)
    z = height + slope * x[None, :] + 0.0 * y[:, None]
    return PalateSurface(x, y, z)


def test_only_sensors_within_reach_below_the_palate_move_and_they_move_onto_it():
    palate = _tilted_palate()
    rest = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [-0.02, 0.0, 0.0], [0.0, 0.01, 0.0]])
    # heights below the palate (m): 0.5 mm, 2 mm, 0.2 mm above it, 0.99 mm; measured along the normal
    cos = 1.0 / np.sqrt(1.0 + 0.2 ** 2)
    below = np.array([0.5e-3, 2e-3, -0.2e-3, 0.99e-3]) / cos
    surface = 0.02 + 0.2 * rest[:, 0]
    disp = np.zeros((3, 4, 3))
    disp[:, :, 2] = surface - below - rest[:, 2]
    disp[2, 3] = np.nan  # a dropout stays one
    contact = {"palate": palate, "jaw_offset": np.zeros((3, 3))}
    held, info = held_to_palate(contact, rest, disp, TOUCH_REACH, ["A", "B", "C", "D"])
    gap, _ = palate.clearance((rest[None] + held).reshape(-1, 3))
    gap = gap.reshape(3, 4)
    np.testing.assert_allclose(gap[:, 0], 0.0, atol=1e-12)  # held onto the palate
    np.testing.assert_allclose(gap[:2, 3], 0.0, atol=1e-12)
    np.testing.assert_array_equal(held[:, 1], disp[:, 1])  # 2 mm below: left as measured
    np.testing.assert_array_equal(held[:, 2], disp[:, 2])  # above the palate: the sensors win, as measured
    assert np.isnan(held[2, 3]).all()
    assert info["frames"] == {"A": 3, "D": 2}
    assert info["largest_move_mm"] == pytest.approx(0.99, abs=1e-9)
    # the move is along the palate's normal, not straight up: x changes on the tilted palate
    assert abs(held[0, 0, 0] - disp[0, 0, 0]) > 1e-6


def test_the_jaw_offset_is_where_the_palate_is_asked():
    palate = _tilted_palate(slope=0.0)
    rest = np.zeros((1, 3))
    disp = np.zeros((2, 1, 3))
    disp[:, 0, 2] = 0.02 - 0.5e-3  # 0.5 mm under the palate in the jaw's frame ...
    jaw = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -0.01]])  # ... but the jaw 10 mm down in frame 1
    held, info = held_to_palate({"palate": palate, "jaw_offset": jaw}, rest, disp, TOUCH_REACH, ["TT"])
    assert held[0, 0, 2] == pytest.approx(0.02) and held[1, 0, 2] == disp[1, 0, 2]
    assert info["frames"] == {"TT": 1}


@pytest.mark.skipif(not OPTI.exists(), reason=f"the shared Opti-Speech recordings are not at {OPTI}")
def test_on_a_real_ka_every_frame_with_a_sensor_at_the_palate_has_the_tongue_touching_it(tmp_path):
    from tonguevis.workflows import open_recording
    from tonguevis.workflows.palate import palate_from_traces
    from tonguevis.sim.settings import RunSettings, build_model
    from tonguevis.workflows.simulation import simulate_recording

    traces = sorted(OPTI.glob("00[234]_*.tsv"))
    palate = palate_from_traces(traces)
    rec = open_recording(OPTI / "006_OSN12_Kah_nofb_natural_take2_HR.tsv")
    motion = simulate_recording(rec, build_model(), RunSettings(palate=palate))
    sensors = motion.targets + motion.jaw_offset[:, None]  # where measured, as drawn
    gap, _ = motion.palate.clearance(sensors.reshape(-1, 3))
    gap = gap.reshape(sensors.shape[:2])
    near = (np.nan_to_num(gap, nan=1.0) <= TOUCH_REACH).any(axis=1)
    assert near.sum() > 100  # the dorsum reaches the palate at the /k/ closures
    area = np.asarray(motion.contact_area)
    assert (area[near] > 0).all(), f"{int((area[near] <= 0).sum())} of {int(near.sum())} frames do not touch"
    held = motion.metadata["contact"]["sensors_held_to_palate"]
    assert held["frames"] and held["largest_move_mm"] <= 1e3 * TOUCH_REACH
    # the sensors are drawn where measured: the misfit says the hold, at most the reach
    assert motion.metadata["plausibility"]["sensor_misfit_max_mm"] <= 1e3 * TOUCH_REACH + 1e-9


def test_the_raise_says_what_each_sensor_alone_would_call_for():
    """A flat roof at z = 0; the front sensor never above it, the back one up to 5 mm above in half the
    frames: raised 5 mm, and the summary says the sensors disagree (the roof left too high at the front)."""
    from types import SimpleNamespace

    from tonguevis.sim.plausibility import contact_line, raise_spread
    from tonguevis.sim.simulate import _register_palate

    x = y = np.linspace(-0.05, 0.05, 101)
    roof = PalateSurface(x, y, np.zeros((101, 101)))
    frames = 200
    displacement = np.zeros((frames, 2, 3))
    displacement[::2, 1, 2] = 0.006  # the back sensor 5 mm above the roof in every other frame
    prep = SimpleNamespace(names=["TT", "TD"], aligned_rest=np.array([[0.02, 0.0, -0.001], [-0.02, 0.0, -0.001]]),
                           displacement=displacement, jaw_offset=np.zeros((frames, 3)))
    raised, shift = _register_palate(roof, prep, quiet=True)
    assert shift == pytest.approx(0.005)
    assert raised.metadata["raise_by_sensor_mm"] == {"TT": 0.0, "TD": pytest.approx(5.0)}
    words = raise_spread(raised.metadata["raise_by_sensor_mm"])
    assert "TD alone calls for 5.0 mm, TT for 0.0 mm" in words and "too high where TT is" in words
    assert raise_spread({"TT": 1.0, "TD": 3.5}) == ""  # within 3 mm: nothing to say
    summary = contact_line({"contact": {"penetration_max_mm": 0.0, "frames_in_contact": 0,
                                           "contact_area_max_mm2": 0.0, "sensors_above_palate": {},
                                           "palate_raised_mm": 5.0, "palate": {"raise_by_sensor_mm":
                                                                               raised.metadata["raise_by_sensor_mm"]}}})
    assert "palate raised 5.0 mm" in summary and "TD alone calls for 5.0 mm" in summary
