"""Palate traces recorded without head references are registered to each other by their shape: a palate is
rigid, so two traces over the same place must agree (issue 36: the midsagittal trace was 1.5 mm from the palate
simulated against in front, the scribble lying 1-2 mm above it there)."""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.io import Recording
from tonguevis.io.registry import write_recording


def _dome(x, y):
    """A palate-like vault (m): 12 mm high at the midline, falling off to the sides and the back."""
    return 0.012 - 18.0 * y ** 2 - 4.0 * (x - 0.01) ** 2


def _turn(pitch_deg: float, roll_deg: float) -> np.ndarray:
    p, r = np.radians(pitch_deg), np.radians(roll_deg)
    about_y = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    about_x = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    return about_x @ about_y


def _scribble(seed: int, n: int = 1500) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-0.005, 0.03, n), rng.uniform(-0.015, 0.015, n)
    return np.column_stack([x, y, _dome(x, y)])


def _moved(points, rotation, shift):
    centre = np.array([0.012, 0.0, 0.008])
    return (points - centre) @ rotation.T + centre + shift


def _write(path, probe):
    n = len(probe)
    rec = Recording(rate=100.0, times=np.arange(n) / 100.0, sensors={"PROBE": probe}, metadata={"file": str(path)})
    write_recording(rec, path)
    return path


def test_a_tilted_trace_is_laid_back_onto_the_surface_of_the_others():
    """A scribble turned by 3 degrees of pitch and 2 of roll and lifted 1 mm: three rounds of the rigid fit put
    every point back on the dome within 0.1 mm (it was up to 2.6 mm off)."""
    from tonguevis.palate import GRID_STEP, _fit_palate, rigid_fit_to_surface

    others = _scribble(1)
    surface = _fit_palate(others, 0.0, 1e-6, GRID_STEP, None)
    truth = _scribble(2)
    moved = _moved(truth, _turn(3.0, 2.0), np.array([0.0, 0.0, 1e-3]))
    assert np.abs(moved[:, 2] - _dome(moved[:, 0], moved[:, 1])).max() > 2e-3
    for _ in range(3):
        rotation, translation, info = rigid_fit_to_surface(moved, surface, others)
        moved = moved @ rotation.T + translation
    assert np.abs(moved[:, 2] - _dome(moved[:, 0], moved[:, 1])).max() < 1e-4
    assert info["rms_after_mm"] < 0.05


def test_a_line_across_the_palate_is_not_pitched():
    """A coronal line (2 mm wide front to back) cannot tell its pitch: only its height and roll are fitted."""
    from tonguevis.palate import GRID_STEP, _fit_palate, rigid_fit_to_surface

    others = _scribble(3)
    surface = _fit_palate(others, 0.0, 1e-6, GRID_STEP, None)
    rng = np.random.default_rng(4)
    y = np.linspace(-0.014, 0.014, 400)
    x = 0.012 + rng.uniform(-1e-3, 1e-3, len(y))
    line = _moved(np.column_stack([x, y, _dome(x, y)]), _turn(0.0, 2.5), np.array([0.0, 0.0, 0.5e-3]))
    _, _, info = rigid_fit_to_surface(line, surface, others)
    assert info["pitch_deg"] == 0.0
    assert info["roll_deg"] == pytest.approx(-2.5, abs=0.3)
    assert info["shift_mm"] < 0  # back down onto the dome
    assert rigid_fit_to_surface(line[:20], surface, others) is None  # too little overlap to tell


def test_traces_without_head_references_are_fitted_as_one_palate(tmp_path):
    """Two scribbles of one dome, the second's sitting turned by 4 degrees and 1.5 mm up, neither with head
    references: the palate fitted from both lies on the dome (as without the registration it does not), and its
    metadata say how far the second trace was moved and by what."""
    from tonguevis.workflows import palate as workflow

    first = _write(tmp_path / "a.csv", _scribble(5))
    second = _write(tmp_path / "b.csv", _moved(_scribble(6), _turn(4.0, 0.0), np.array([0.0, 0.0, 1.5e-3])))
    both = workflow.palate_from_traces([first, second], probe="PROBE")
    said = both.metadata["trace_registration_mm"][str(second)]
    assert said["by"].startswith("registered to the other traces")
    assert said["turn_deg"] == pytest.approx(4.0, abs=0.3)
    assert said["rms_to_the_others_mm"][1] < 0.3 * said["rms_to_the_others_mm"][0]
    probe = _scribble(7, 300)
    probe = probe[(probe[:, 0] > 0.0) & (probe[:, 0] < 0.025)]
    registered = np.nanmax(np.abs(both.clearance(probe)[0]))
    original = workflow.registered_by_shape
    try:
        workflow.registered_by_shape = lambda points: ({}, {})
        as_recorded = workflow.palate_from_traces([first, second], probe="PROBE")
    finally:
        workflow.registered_by_shape = original
    assert registered < 0.3e-3 < np.nanmax(np.abs(as_recorded.clearance(probe)[0]))


def test_traces_that_disagree_by_centimetres_are_taken_as_recorded_and_said_so(tmp_path):
    from tonguevis.workflows.palate import MAX_TRACE_MOVE, palate_from_traces

    first = _write(tmp_path / "a.csv", _scribble(8))
    second = _write(tmp_path / "b.csv", _moved(_scribble(9), _turn(0.0, 0.0), np.array([0.0, 0.0, 2 * MAX_TRACE_MOVE])))
    said = palate_from_traces([first, second], probe="PROBE").metadata["trace_registration_mm"][str(second)]
    assert said["by"].startswith("not registered")
    assert said["largest_move_mm"] > 1e3 * MAX_TRACE_MOVE


def test_the_shared_opti_speech_traces_agree_once_registered():
    """OSN12's traces 002-004 (no head references): the midsagittal trace in front of x = -15 mm lies within
    1 mm (median) of the palate fitted from all three (1.5 mm as recorded), and the fit's RMS falls."""
    from tests.conftest import shared_file
    from tonguevis.palate import trace_points
    from tonguevis.workflows.palate import palate_from_traces
    from tonguevis.workflows.recording import open_recording

    traces = [shared_file("ema", "optispeech", f) for f in (
        "002_OSN12_Palate_MidSagital_HR.tsv", "003_OSN12_Palate_Coronal_HR.tsv", "004_OSN12_Palate_Scribble_HR.tsv")]
    surface = palate_from_traces(traces)
    said = surface.metadata["trace_registration_mm"]
    assert all(said[str(p)]["by"].startswith("registered to the other traces") for p in traces[1:])
    midline = trace_points(open_recording(traces[0], audio=False), "PROBE")
    front = midline[midline[:, 0] >= -15e-3]
    assert np.nanmedian(np.abs(surface.clearance(front)[0])) < 1e-3
    assert surface.metadata["rms_m"] < 0.7e-3  # 0.76 mm as recorded
