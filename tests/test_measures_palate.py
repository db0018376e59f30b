"""Which palate the measures use (issue 35): a speaker's as traced, registered by head references when both
recordings have them and never raised; the generic one placed in the speaker; none."""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_palate_head_frame import REFS, _rotation, _trace
from tonguevis.io import Recording
from tonguevis.workflows.measures import measurement_palate


def _speech(tip: np.ndarray) -> Recording:
    """A still speech recording in the traces' first sitting: the head references where they were, TT at ``tip``."""
    n = 300
    sensors = {name: np.tile(p, (n, 1)) for name, p in REFS.items()} | {"TT": np.tile(tip, (n, 1))}
    return Recording(rate=100.0, times=np.arange(n) / 100.0, sensors=sensors)


def test_a_palate_from_another_sitting_is_registered_not_raised(tmp_path):
    from tonguevis.analysis.constriction import constriction
    from tonguevis.workflows.palate import palate_from_traces

    here = palate_from_traces([_trace(tmp_path / "a.csv", np.eye(3), np.zeros(3), 1)], probe="PROBE")
    there = palate_from_traces([_trace(tmp_path / "b.csv", _rotation(10.0), np.array([0.012, 0.003, -0.02]), 2)],
                               probe="PROBE")
    tip = np.array([0.012, 0.0, 0.02])  # 8 mm *above* the dome's crest (12 mm): a palate the simulation would raise
    measured = measurement_palate(_speech(tip), there)
    assert "registered" in measured.notes[0] and measured.label.startswith("speaker's palate")
    degree = constriction(measured.surface, tip[None]).degree[0]
    truth = constriction(here, tip[None]).degree[0]
    assert truth < -7e-3 and degree == pytest.approx(truth, abs=1e-3)  # where it was traced: above it, not raised
    unregistered = constriction(there, tip[None]).degree[0]
    assert abs(unregistered - truth) > 5e-3


def test_generic_and_none(tmp_path):
    from tonguevis.paths import DATA_DIR
    from tonguevis.workflows import open_recording

    path = DATA_DIR / "spk1_ta.tsv"
    if not path.exists():
        pytest.skip(f"demo corpus not built: {path}")
    recording = open_recording(path)
    generic = measurement_palate(recording, "generic")
    assert generic.label == "generic palate" and "estimate" in generic.notes[0]
    assert generic.surface.metadata.get("generic")
    assert measurement_palate(recording, "none").surface is None and measurement_palate(recording, None).label == ""


def test_a_speaker_the_generic_palate_cannot_be_placed_in_gets_no_constriction():
    times = np.arange(500) / 100.0
    tip = np.column_stack([0 * times, 0 * times, 0.005 * np.sin(3 * times)])
    recording = Recording(rate=100.0, times=times, sensors={"TT": tip})  # one tongue sensor: no alignment
    measured = measurement_palate(recording, "generic")
    assert measured.surface is None and "cannot be placed" in measured.notes[0] and "too few" in measured.notes[0]
