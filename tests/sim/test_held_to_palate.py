"""A sensor within 1 mm under the palate is held to it (the coil between tongue and palate), and the
tongue then touches the palate there: contact area above zero in every such frame (issue 23 item 4).  Held
to it means onto it, the contact's margin below it (the contact keeps the tongue that far below)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tonguevis.palate import PalateSurface
from tonguevis.sim.contact import MARGIN
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
    np.testing.assert_allclose(gap[:, 0], MARGIN, atol=1e-12)  # held onto the palate, the margin below it
    np.testing.assert_allclose(gap[:2, 3], MARGIN, atol=1e-12)
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
    assert held[0, 0, 2] == pytest.approx(0.02 - MARGIN) and held[1, 0, 2] == disp[1, 0, 2]
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
    lift = np.repeat(motion.velum_lift, sensors.shape[1])  # each frame's palate: its velum lifted
    gap, _ = motion.palate.clearance(sensors.reshape(-1, 3), lift=lift)
    gap = gap.reshape(sensors.shape[:2])
    near = (np.nan_to_num(gap, nan=1.0) <= TOUCH_REACH).any(axis=1)
    assert near.sum() > 100  # the dorsum reaches the palate at the /k/ closures
    area = np.asarray(motion.contact_area)
    assert (area[near] > 0).all(), f"{int((area[near] <= 0).sum())} of {int(near.sum())} frames do not touch"
    held = motion.metadata["contact"]["sensors_held_to_palate"]
    assert held["frames"] and held["largest_move_mm"] <= 1e3 * TOUCH_REACH
    # the sensors are drawn where measured: the misfit says the hold, at most the reach
    assert motion.metadata["plausibility"]["sensor_misfit_max_mm"] <= 1e3 * TOUCH_REACH + 1e-9
