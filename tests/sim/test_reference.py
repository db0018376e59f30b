"""Head frame and jaw frame (tonguevis.sim.reference), and the palate placed for the views as simulate() placed it."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from tests.sim.test_simulate import _recording, model  # noqa: F401 (model: a fixture)
from tonguevis.sim import simulate
from tonguevis.sim.reference import check_reference, describe, export_note, jaw_moves, tongue_offset


def test_a_tongue_riding_on_the_jaw_moves_in_the_head_frame_and_stays_in_the_jaw_frame(model):  # noqa: F811
    """Known answer: the jaw drops 10 mm (in the model's frame; the recording sees it rotated and scaled) and carries
    the tongue, which does not deform."""
    motion = simulate(_recording(model, raise_m=0.0, jaw_m=0.01), model, modes=20, landmarks="rule", frame="model")
    assert jaw_moves(motion)
    head, jaw = tongue_offset(motion, "head"), tongue_offset(motion, "jaw")
    assert np.abs(jaw).max() == 0.0
    np.testing.assert_allclose(head, motion.jaw_offset)
    # In the model frame the jaw went straight down by 10 mm (the alignment undoes the device's rotation and scale).
    deepest = int(np.argmax(np.linalg.norm(head, axis=1)))
    np.testing.assert_allclose(head[deepest], [0.0, 0.0, -0.01], atol=1e-5)
    # The head-frame tongue is where the sensors were measured: rest + (no deformation) + the jaw's drop.
    tip = list(motion.sensor_names).index("TT")
    node = motion.sensor_nodes[tip]
    in_head = motion.deformed_points(deepest)[node] + head[deepest]
    np.testing.assert_allclose(in_head, model.mesh.points[node] + [0.0, 0.0, -0.01], atol=1e-5)


def test_without_jaw_motion_the_two_frames_coincide_and_say_so(model):  # noqa: F811
    motion = simulate(_recording(model, jaw_m=0.0), model, modes=20, landmarks="rule")
    assert not jaw_moves(motion)
    assert np.abs(tongue_offset(motion, "head")).max() == 0.0
    assert describe("head", moves=False) == "head frame = jaw frame (no jaw motion recorded)"
    assert "same in the head and the jaw frame" in export_note("head", False)


def test_frame_names_are_checked_and_described():
    assert check_reference("head") == "head" and check_reference("jaw") == "jaw"
    with pytest.raises(ValueError, match="head, jaw"):
        check_reference("skull")
    assert describe("head").startswith("head frame") and "palate fixed" in describe("head")
    assert describe("jaw").startswith("jaw frame") and "removed" in describe("jaw")
    note = export_note("head", True)
    assert note.startswith("Frame of reference: head frame") and "\ndeformation = " in note and "jaw_offset.csv" in note


def test_the_views_palate_is_the_one_simulate_used(model, monkeypatch):  # noqa: F811
    """placed_palate (for drawing) and simulate (for contact) place a speaker's palate through one function."""
    from tonguevis.palate import PalateSurface
    from tonguevis.workflows import rest_of

    module = importlib.import_module("tonguevis.sim.palate_placement")  # where the simulation places it
    rec = _recording(model, raise_m=0.004, jaw_m=0.003)
    tt = rec.sensors["TT"]
    x = np.arange(-0.2, 0.2, 0.002)
    palate = PalateSurface(x, x.copy(), np.full((len(x), len(x)), np.nanmax(tt[:, 2]) + 0.004))  # recording frame
    used = []
    original = module.place_palate
    monkeypatch.setattr(module, "place_palate", lambda *a, **k: used.append(original(*a, **k)) or used[-1])
    motion = simulate(rec, model, modes=20, landmarks="rule", palate=palate)
    placed, lift, info = module.placed_palate(rec, palate, model, landmarks="rule", rest=rest_of(motion))
    (surface, used_lift, used_info), _ = used
    for name in ("rotation", "translation", "z", "lift_shape"):
        np.testing.assert_allclose(getattr(placed, name), getattr(surface, name), atol=1e-15)
    assert placed.scale == surface.scale and info == used_info
    np.testing.assert_array_equal(lift, used_lift)
    assert motion.metadata["contact"]["palate_raised_mm"] == pytest.approx(info["traced_raised_mm"])
    # A palate already in the model frame (the generic one) is used as is there, and placed with the model in
    # the speaker frame (the default).
    as_is = PalateSurface(x, x.copy(), palate.z, metadata={"frame": "model"})
    same, none, _ = module.placed_palate(rec, as_is, model, landmarks="rule", rest=rest_of(motion), frame="model")
    assert same is as_is and none is None
    moved, none, _ = module.placed_palate(rec, as_is, model, landmarks="rule", rest=rest_of(motion))
    placement = motion.model.placement
    assert none is None and moved.scale == pytest.approx(placement.scale)
    np.testing.assert_allclose(moved.rotation, placement.rotation, atol=1e-12)
