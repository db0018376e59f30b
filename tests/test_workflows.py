"""The workflow layer: one way to open, find the rest, simulate and find productions, for every front end."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from tests.conftest import REPO
from tonguevis.errors import RecordingError
from tonguevis.paths import DATA_DIR

DEMO = DATA_DIR / "spk1_ta.tsv"


def test_workflows_does_not_import_qt():
    code = ("import sys, tonguevis.workflows as w; w.open_recording; "
            "qt = sorted(m for m in sys.modules if m.split('.')[0] in ('PySide6', 'PyQt5', 'PyQt6', 'pyvistaqt'))\n"
            "assert not qt, qt")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]


def _demo():
    from tonguevis.workflows import open_recording

    if not DEMO.exists():
        pytest.skip(f"demo corpus not built: {DEMO}")
    return open_recording(DEMO)


def _cut(rec, start: float, end: float):
    keep = (rec.times >= start) & (rec.times <= end)
    return replace(rec, times=rec.times[keep] - rec.times[keep][0], audio=None, labels=[],
                   sensors={n: v[keep] for n, v in rec.sensors.items()},
                   orientations={n: v[keep] for n, v in rec.orientations.items()})


def _nodding(rec, degrees: float = 20.0, hz: float = 1.0):
    """``rec`` with the whole head pitching up and down (every sensor, references included)."""
    angle = np.radians(degrees) * np.sin(2 * np.pi * hz * rec.times)
    c, s = np.cos(angle), np.sin(angle)
    rotation = np.zeros((len(angle), 3, 3))
    rotation[:, 0, 0], rotation[:, 0, 2], rotation[:, 1, 1] = c, -s, 1.0
    rotation[:, 2, 0], rotation[:, 2, 2] = s, c
    pivot = np.array([-0.08, 0.0, -0.05])  # a neck behind and below the sensors
    sensors = {n: np.einsum("nij,nj->ni", rotation, p - pivot) + pivot for n, p in rec.sensors.items()}
    return rec.with_sensors(sensors)


def test_productions_are_found_on_the_head_corrected_recording():
    from tonguevis.workflows import find_recording_productions, head_corrected, head_references

    rec = _demo()
    assert head_references(rec) == ["REF1", "REF2", "REF3"]
    still = find_recording_productions(rec)
    nodding = _nodding(rec)
    corrected = find_recording_productions(nodding)
    assert len(corrected) == len(still) == 15
    np.testing.assert_allclose([p.release for p in corrected], [p.release for p in still], atol=1e-4)
    raw = find_recording_productions(nodding, head_correction=False)  # what the app used to do
    assert len(raw) != len(still)  # the nod lifts and lowers the tip: releases lost or invented
    # Fewer than three references: nothing to correct with.
    two = rec.with_sensors({n: v for n, v in rec.sensors.items() if n != "REF3"})
    assert head_references(two) == [] and head_corrected(two) is two


def test_simulate_recording_never_dead_ends_and_records_the_rest():
    from tests.gui.conftest import block_model
    from tonguevis.workflows import RestChoice, rest_of, simulate_recording

    speech = _cut(_demo(), 5.2, 7.7)  # speech from the first frame, 2.5 s
    model = block_model()
    motion = simulate_recording(speech, model, modes=40, landmarks="rule")
    rest = rest_of(motion)
    assert rest.how == "stillest window" and rest.reason == "no still second in the recording"
    assert motion.metadata["rest"] == {"interval": list(rest.interval), "how": "stillest window",
                                       "reason": "no still second in the recording"}
    given = simulate_recording(speech, model, modes=40, landmarks="rule", rest=(0.3, 0.6))
    assert rest_of(given) == RestChoice((0.3, 0.6), "given")
    with pytest.raises(RecordingError, match="not inside the recording"):
        simulate_recording(speech, model, modes=40, landmarks="rule", rest=(2.0, 3.0))


def test_prepare_targets_takes_a_rest_choice_as_is():
    from tests.gui.conftest import block_model
    from tonguevis.preprocess import RestChoice, prepare_targets

    rec = _demo()
    choice = RestChoice((1.0, 2.0), "detected")
    prep = prepare_targets(rec, block_model(), "rule", rest=choice)
    assert prep.rest is choice and prep.rest_interval == (1.0, 2.0)
    assert prepare_targets(rec, block_model(), "rule").rest.how == "detected"  # the demo rests 5 s


def test_the_app_finds_productions_as_the_workflow_does():
    pytest.importorskip("PySide6")
    from tonguevis.workflows.session import make_session
    from tonguevis.workflows import find_recording_productions

    nodding = _nodding(_demo())
    session = make_session(nodding)
    expected = find_recording_productions(nodding, keep=None)  # the app marks every production
    assert [p.release for p in session.production_table] == [p.release for p in expected]
    assert len(expected) > len(find_recording_productions(nodding))  # more than the paper's 2nd-4th


def test_simulate_recording_takes_every_run_setting_as_a_keyword():
    """frame=, tongue_size=, rest_fit= ... change the run settings as modes= does (they went to simulate()
    beside the settings' own and raised 'got multiple values')."""
    from tonguevis.sim import TongueModel
    from tonguevis.workflows import open_recording, simulate_recording

    rec = open_recording(DEMO)
    model = TongueModel.default()
    in_model = simulate_recording(rec, model, modes=20, frame="model")
    assert in_model.metadata["fit"]["frame"] == "model"
    generic = simulate_recording(rec, model, modes=20, tongue_size=1.0, sensor_patches=None)
    assert generic.metadata["fit"]["size_from"] == "given" and generic.metadata["fit"]["tongue_size"] == 1.0
