"""simulate(): recordings in, motions out, on a small bar model."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.sim._models import bar_model
from tonguevis.errors import SimulationError
from tonguevis.io import Recording
from tonguevis.sim import Motion, simulate

SENSORS = ("TT", "TD", "TL", "TR")


def _recording(model, raise_m=0.015, jaw_m=0.0, rate=100.0, seconds=4.0, extra=None):
    """Sensors on the model's nodes, seen through a made-up device frame (rotated, scaled, shifted, mm-like)."""
    n = int(seconds * rate)
    t = np.arange(n) / rate
    bump = np.where((t > 2.0) & (t < 3.0), np.sin(np.pi * (t - 2.0)) ** 2, 0.0)
    device = Rotation.from_rotvec([0.2, -0.4, 0.9])
    scale = 1.15  # the speaker's tongue is a bit smaller than the model
    jaw = np.zeros((n, 3))
    jaw[:, 2] = -jaw_m * bump
    sensors = {}
    for name in SENSORS:
        node = model.mesh.points[model.landmarks.sensors[name]]
        pos = np.repeat(node[None], n, axis=0)
        if name == "TT":
            pos[:, 2] += raise_m * bump
        pos += jaw  # the jaw carries the tongue
        sensors[name] = device.apply(pos / scale) + [0.1, -0.02, 0.05]
    sensors["JAW"] = device.apply((np.array([0.0, 0.01, 0.0]) + jaw) / scale) + [0.1, -0.02, 0.05]
    for name, pos in (extra or {}).items():
        sensors[name] = pos
    return Recording(rate=rate, times=t, sensors=sensors, metadata={"file": "synthetic", "format": "test"})


@pytest.fixture(scope="module")
def model():
    return bar_model(sensors=SENSORS)


def test_sensors_follow_the_recording_and_the_tongue_returns_to_rest(model):
    motion = simulate(_recording(model), model, modes=20, landmarks="rule", sensor_stiffness=None, frame="model")
    assert motion.converged.all()
    assert np.nanmax(motion.sensor_residual) < 1e-5  # 0.01 mm
    assert motion.metadata["alignment_scale"] == pytest.approx(1.15, rel=1e-6)
    assert motion.metadata["alignment_rms_m"] < 1e-6  # the detected rest window ends as the motion starts
    tip = list(motion.sensor_names).index("TT")
    assert np.abs(motion.targets[:, tip, 2] - motion.targets[0, tip, 2]).max() == pytest.approx(0.015, rel=1e-3)
    assert motion.energy.max() > 0 and (motion.energy >= 0).all()
    assert np.abs(motion.displacement(motion.n_frames - 1)).max() < 1e-5


def test_jaw_motion_is_removed_before_driving_the_tongue(model):
    still = simulate(_recording(model, raise_m=0.0, jaw_m=0.01), model, modes=20, landmarks="rule")
    assert np.abs(still.displacements()).max() < 1e-9  # the whole tongue rode on the jaw: no deformation


def test_missing_tongue_sensors_are_an_error_and_unknown_ones_are_ignored(model):
    rec = _recording(model)
    only_tip = rec.with_sensors({"TT": rec.sensors["TT"], "JAW": rec.sensors["JAW"]})
    with pytest.raises(SimulationError, match="too few tongue sensors"):
        simulate(only_tip, model, modes=20, landmarks="rule")
    with_tb = _recording(model, extra={"TB": rec.sensors["TD"] + 0.001})
    motion = simulate(with_tb, model, modes=20, landmarks="rule")
    assert motion.metadata["ignored_sensors"] == ["TB"]
    assert "TB" not in motion.sensor_names


def test_compiled_and_reference_loops_give_the_same_motion(model):
    rec = _recording(model, raise_m=0.03)
    fast = simulate(rec, model, modes=20, landmarks="rule")
    slow = simulate(rec, model, modes=20, landmarks="rule", backend="numpy")
    assert np.abs(fast.q - slow.q).max() < 1e-10 * np.abs(slow.q).max()


def test_motion_round_trips_through_npz_and_writes_a_vtk_series(model, tmp_path):
    import meshio

    motion = simulate(_recording(model, seconds=3.0), model, modes=20, landmarks="rule")
    motion.save(tmp_path / "m.npz")
    back = Motion.load(tmp_path / "m.npz")
    np.testing.assert_array_equal(back.q, motion.q)
    assert back.sensor_names == motion.sensor_names
    np.testing.assert_allclose(back.displacement(250), motion.displacement(250), atol=1e-15)
    pvd = motion.to_vtk_series(tmp_path / "vtk", frames=slice(0, 300, 100))
    frames = sorted((tmp_path / "vtk").glob("*.vtu"))
    assert pvd.exists() and len(frames) == 3
    mesh = meshio.read(frames[2])
    np.testing.assert_allclose(mesh.points, motion.deformed_points(200), atol=1e-12)


def test_a_file_that_is_not_a_motion_is_refused(tmp_path):
    bad = tmp_path / "x.npz"
    np.savez(bad, q=np.zeros(3))
    with pytest.raises(SimulationError):
        Motion.load(bad)
    (tmp_path / "y.npz").write_bytes(b"not a zip")
    with pytest.raises(SimulationError, match="y.npz"):
        Motion.load(tmp_path / "y.npz")


def test_nearest_frame_rounds_and_clips():
    from tonguevis.sim.motion import nearest_frame

    times = np.array([0.0, 0.01, 0.02, 0.03])
    assert [nearest_frame(times, t) for t in (-1.0, 0.004, 0.006, 0.0149, 0.03, 5.0)] == [0, 0, 1, 1, 3, 3]


def test_dropped_frames_come_back_on_the_uniform_clock_and_are_bridged(model):
    """A recorder that drops frames: the simulation's step stays 1/rate, the lost frames are bridged."""
    from dataclasses import replace

    rec = _recording(model)
    keep = np.ones(rec.n_samples, dtype=bool)
    keep[[40, 41, 90]] = False  # three frames lost (two in a row), times jittered by up to 0.3 ms
    jitter = np.random.default_rng(1).uniform(-3e-4, 3e-4, rec.n_samples)
    lossy = replace(rec, times=(rec.times + jitter)[keep], sensors={k: v[keep] for k, v in rec.sensors.items()})
    motion = simulate(lossy, model, modes=20, landmarks="rule")
    assert motion.n_frames == rec.n_samples
    np.testing.assert_allclose(np.diff(motion.times), 1.0 / rec.rate, rtol=1e-9)
    bridged = motion.metadata["dropouts"]["bridged_gaps"]
    assert bridged == 2 * len(motion.sensor_names) and motion.metadata["dropouts"]["released_frames"] == 0
    full = simulate(rec, model, modes=20, landmarks="rule")
    assert np.abs(motion.energy - full.energy).max() < 0.05 * full.energy.max()


def test_a_recording_in_the_devices_frame_is_noted_not_warned_on_every_command(model, caplog):
    """NDI Wave and Carstens files without axes come in the device's frame: the alignment guesses. `tonguevis
    info` and the app's status bar say so (tonguevis.io.recording.unstated_axes_note), not every simulation
    as a warning (issue 27, item 4)."""
    import logging

    caplog.set_level(logging.INFO, logger="tonguevis")
    rec = _recording(model)
    rec.metadata["frame"] = "device"
    simulate(rec, model, modes=20, landmarks="rule")
    said = [r for r in caplog.records if "device's frame" in r.getMessage()]
    assert said and all(r.levelno < logging.WARNING for r in said)


def test_simulate_takes_the_clis_stiffness_words():
    """'hard' means the paper's hard constraints in the library as on the command line; a wrong word is
    a SimulationError naming the words (it ended in NumPy's "ufunc 'isfinite' not supported")."""
    from tonguevis.errors import SimulationError
    from tonguevis.io import read_recording
    from tonguevis.paths import DATA_DIR
    from tonguevis.sim import TongueModel, simulate

    rec = read_recording(DATA_DIR / "spk1_ta.tsv", sensor_map=DATA_DIR / "sensor_map.json")
    short = rec.with_sensors({k: v[:400] for k, v in rec.sensors.items()}, times=rec.times[:400], audio=None,
                             orientations={})
    motion = simulate(short, TongueModel.default(), modes=100, sensor_stiffness="hard")
    assert motion.metadata["sensor_stiffness"] is None
    with pytest.raises(SimulationError, match="hard"):
        simulate(short, TongueModel.default(), modes=10, sensor_stiffness="soft")
