"""A palate traced in another sitting is registered into the speech's head frame by the head references
(issue 23, item 3)."""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.io import Recording
from tonguevis.io.registry import write_recording
from tonguevis.preprocess.correction import register_references

REFS = {"REF1": np.array([0.02, 0.04, 0.03]), "REF2": np.array([0.02, -0.04, 0.03]),
        "REF3": np.array([-0.06, 0.0, 0.05])}


def _dome(x, y):
    """A palate-like vault (m): 12 mm high at the midline, falling off to the sides and the back."""
    return 0.012 - 18.0 * y ** 2 - 4.0 * (x - 0.01) ** 2


def _rotation(degrees: float) -> np.ndarray:
    a = np.radians(degrees)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def _trace(path, rotation, translation, seed: int):
    """A probe scribbled over the dome, with three still head references, all seen in a head frame
    moved by (rotation, translation): another sitting."""
    rng = np.random.default_rng(seed)
    n = 1500
    x, y = rng.uniform(-0.005, 0.03, n), rng.uniform(-0.015, 0.015, n)
    probe = np.column_stack([x, y, _dome(x, y)])
    sensors = {name: np.tile(p, (n, 1)) for name, p in REFS.items()} | {"PROBE": probe}
    sensors = {name: v @ rotation.T + translation for name, v in sensors.items()}
    rec = Recording(rate=100.0, times=np.arange(n) / 100.0, sensors=sensors, metadata={"file": str(path)})
    write_recording(rec, path)
    return path


def test_register_references_recovers_a_rigid_motion():
    rotation, translation = _rotation(12.0), np.array([0.01, -0.004, 0.015])
    moved = {n: rotation @ p + translation for n, p in REFS.items()}
    r, t, residual, names = register_references(REFS, moved)
    assert np.allclose(r, rotation, atol=1e-12) and np.allclose(t, translation, atol=1e-12)
    assert residual < 1e-12 and sorted(names) == sorted(REFS)
    assert register_references({"REF1": REFS["REF1"]}, moved) is None


def test_a_palate_from_another_sitting_lands_where_the_speech_head_frame_has_it(tmp_path):
    from tonguevis.sim.simulate import _by_head_references
    from tonguevis.workflows.palate import palate_from_traces

    here = palate_from_traces([_trace(tmp_path / "a.csv", np.eye(3), np.zeros(3), 1)], probe="PROBE")
    rotation, translation = _rotation(10.0), np.array([0.012, 0.003, -0.02])
    there = palate_from_traces([_trace(tmp_path / "b.csv", rotation, translation, 2)], probe="PROBE")
    assert set(there.metadata["head_references"]) == set(REFS)
    speech = {n: np.asarray(v) for n, v in here.metadata["head_references"].items()}  # the speech's sitting
    probe = np.column_stack([np.full(9, 0.012), np.linspace(-0.008, 0.008, 9), np.zeros(9)])
    truth, _ = here.clearance(probe)
    unregistered, _ = there.clearance(probe)
    registered = _by_head_references(there, speech, quiet=True)
    moved, _ = registered.clearance(probe)
    assert np.nanmax(np.abs(unregistered - truth)) > 5e-3  # another sitting: centimetres off as it comes
    assert np.nanmax(np.abs(moved - truth)) < 1e-3  # registered: within the fit's own smoothing
    assert registered.metadata["head_registration"]["residual_mm"] < 1e-6
    assert registered.metadata["head_registration"]["moved_mm"] == pytest.approx(1e3 * np.linalg.norm(
        register_references({n: np.asarray(v) for n, v in there.metadata["head_references"].items()}, speech)[1]))


def test_traces_of_two_sittings_are_fitted_in_one_head_frame(tmp_path):
    from tonguevis.workflows.palate import palate_from_traces

    one = palate_from_traces([_trace(tmp_path / "a.csv", np.eye(3), np.zeros(3), 3)], probe="PROBE")
    both = palate_from_traces([_trace(tmp_path / "a.csv", np.eye(3), np.zeros(3), 3),
                               _trace(tmp_path / "c.csv", _rotation(-8.0), np.array([0.0, 0.01, 0.02]), 4)],
                              probe="PROBE")
    assert both.metadata["trace_registration_mm"][str(tmp_path / "c.csv")] < 1e-6
    probe = np.column_stack([np.full(9, 0.01), np.linspace(-0.008, 0.008, 9), np.zeros(9)])
    assert np.nanmax(np.abs(both.clearance(probe)[0] - one.clearance(probe)[0])) < 1e-3
