"""The shipped tongue and the paper's ArtiSynth tongue, driven by the demo corpus."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import shared_file
from tonguevis import TongueModel, simulate
from tonguevis.io import read_recording
from tonguevis.paths import DATA_DIR


@pytest.fixture(scope="module")
def default_model():
    return TongueModel.default()


@pytest.fixture(scope="module")
def ta():
    return read_recording(DATA_DIR / "spk1_ta.tsv")


@pytest.mark.parametrize("landmarks", ["speaker", "rule"])
def test_hard_constraints_hold_the_demo_sensors_to_a_hundredth_of_a_millimetre(default_model, ta, landmarks):
    motion = simulate(ta, default_model, landmarks=landmarks, sensor_stiffness=None)
    assert motion.converged.all()
    assert np.nanmax(motion.sensor_residual) < 1e-5  # 0.01 mm
    assert set(motion.sensor_names) == {"TT", "TD", "TL", "TR"}
    assert np.abs(motion.volume_change).max() < 0.02  # Fig. 5: about 1 % or less
    tip = motion.sensor_names.index("TT")
    raise_mm = 1e3 * np.ptp(motion.targets[:, tip, 2])
    assert 5 < raise_mm < 25  # the demo /t/ lifts the tip by about a centimetre


def test_default_springs_give_a_believable_tongue_on_the_demo(default_model, ta):
    soft = simulate(ta, default_model, sensor_patches=None)  # the springs' own shape: the modes alone
    hard = simulate(ta, default_model, sensor_stiffness=None, sensor_patches=None)
    p, ph = soft.metadata["plausibility"], hard.metadata["plausibility"]
    assert soft.metadata["sensor_stiffness"] == 20.0
    assert p["amplification"] < 1.5 and p["volume_change_max_percent"] < 1.0
    assert 0.05 < p["sensor_misfit_rms_mm"] < 1.0  # follows, not held
    assert p["amplification"] <= ph["amplification"] + 1e-9  # never swings further than the hard model


def test_the_whole_tongue_returns_to_rest_when_the_sensors_do(default_model, ta):
    """Hold every sensor at its rest pose for the last two seconds: nothing may be left over."""
    still = {}
    for name, pos in ta.sensors.items():
        pos = pos.copy()
        pos[-200:] = np.nanmean(pos[:400], axis=0)  # the rest pose of the first 4 s
        still[name] = pos
    motion = simulate(ta.with_sensors(still), default_model, rest=(0.0, 4.0))
    assert np.abs(motion.displacement(motion.n_frames - 1)).max() < 1e-5  # < 0.01 mm


def test_midsagittal_recordings_drive_the_model(default_model, ta):
    """Haskins-style layouts (no lateral sensors) align in the midsagittal plane."""
    mid = ta.with_sensors({k: v for k, v in ta.sensors.items() if k not in ("TL", "TR")})
    motion = simulate(mid, default_model, modes=40, sensor_stiffness=None)
    assert motion.metadata["midsagittal_alignment"]
    assert motion.converged.all() and np.nanmax(motion.sensor_residual) < 1e-5


def test_the_artisynth_tongue_loads_and_simulates_with_automatic_landmarks(ta):
    from tonguevis.mesh import ARTISYNTH_AXES

    path = shared_file("artisynth", "tongue3.1.node")
    model = TongueModel.from_mesh(path, axes=ARTISYNTH_AXES)
    assert (model.mesh.n_nodes, model.mesh.n_tets) == (1803, 8606)
    assert model.rest_volume == pytest.approx(97.0e-6, rel=0.01)
    basis = model.basis(100)
    assert 0.5 < basis.frequencies_hz[0] < 10  # a soft tongue: first modes of a few Hz
    motion = simulate(ta, model, sensor_stiffness=None)
    assert motion.converged.all()
    assert np.nanmax(motion.sensor_residual) < 1e-5
    assert np.abs(motion.volume_change).max() < 0.02
