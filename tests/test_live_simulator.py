"""The live simulation, frame by frame, equals the replay's on the same recording and rest."""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.io.recording import Recording
from tonguevis.live.simulator import LiveSimulationError, LiveSimulator, _Engagement, stillest_window
from tonguevis.live.source import recording_frames
from tonguevis.paths import DEMO_RECORDING
from tonguevis.preprocess.rest import RestChoice
from tonguevis.sim.dropouts import engagement
from tonguevis.workflows import open_recording
from tonguevis.sim.settings import RunSettings


@pytest.fixture(scope="module")
def demo():
    rec = open_recording(DEMO_RECORDING)
    positions, _, times = recording_frames(rec)  # as the stream carries them: mm, float32 values
    # The replay reads the same numbers the stream sends.
    streamed = Recording(rate=rec.rate, times=times,
                         sensors={n: positions[:, k] / 1000.0 for k, n in enumerate(rec.sensor_names)},
                         metadata=dict(rec.metadata))
    return rec.sensor_names, positions, times, streamed


@pytest.mark.parametrize("rest_fit", [False, True], ids=["placed", "rest-shape-fitted"])
def test_live_frames_equal_the_replay(demo, rest_fit):
    from tonguevis.sim.simulate import simulate

    names, positions, times, streamed = demo
    settings = RunSettings(modes=100, rest_fit=rest_fit)
    sim = LiveSimulator(names, settings, rate=streamed.rate, dtype=np.float64)
    for i in range(300):  # the first 3 s seen: the rest is their stillest half second
        sim.observe(times[i], positions[i])
    sim.take_rest()
    assert len(sim.rest_times) == 51 and sim.rest_times[0] >= times[0] and sim.rest_times[-1] <= times[299]
    live = np.empty((len(times), len(sim.surface_nodes), 3))
    sensors = np.empty((len(times), len(sim.driving_names), 3))
    q = np.empty((len(times), settings.modes))
    for i in range(len(times)):
        step = sim.step(positions[i])
        live[i], sensors[i], q[i] = step.surface, step.sensor_points, step.q
        assert set(step.timings) == {"correct", "drive", "integrate", "reconstruct"}
    rest = RestChoice((float(sim.rest_times[0]), float(sim.rest_times[-1])), "given")
    motion = simulate(streamed, settings, rest=rest)  # sensors on the surface too
    assert motion.metadata["dropouts"]["bridged_gaps"] == 0 and not motion.metadata["recovered_frames"]
    replay = motion.model.mesh.points[sim.surface_nodes][None] + motion.model.displacements(
        motion.q, nodes=sim.surface_nodes)
    assert sim.driving_names == motion.sensor_names
    assert ("rest_fit" in sim.fit) == rest_fit and ("rest_fit" in motion.metadata["fit"]) == rest_fit
    np.testing.assert_array_equal(sim.prep.nodes, motion.sensor_nodes)
    # The tongue moves by centimetres; the two agree to rounding.
    assert np.abs(replay - replay[:1]).max() > 5e-3
    assert np.abs(live - replay).max() < 1e-9
    np.testing.assert_allclose(sensors, motion.targets, atol=1e-12)
    # the modes' coordinates agree; the replay's last ones are its sensor patches, which the live surface has too
    assert motion.metadata["sensor_patches"]["global_modes"] == settings.modes
    modes = motion.q[:, :settings.modes]
    np.testing.assert_allclose(q, modes, rtol=0, atol=1e-9 * np.abs(modes).max())


def test_float32_surface_is_close(demo):
    names, positions, times, _ = demo
    sim = LiveSimulator(names, RunSettings(modes=100), rate=100.0)
    sim.set_rest(times[:51], positions[:51])
    sim64 = LiveSimulator(names, RunSettings(modes=100), rate=100.0, dtype=np.float64)
    sim64.set_rest(times[:51], positions[:51])
    for i in range(0, 600):
        a, b = sim.step(positions[i]), sim64.step(positions[i])
    assert a.surface.dtype == np.float32
    assert np.abs(a.surface - b.surface).max() < 1e-6  # a micrometre: nothing on screen


def test_causal_engagement_equals_the_replays():
    rng = np.random.default_rng(3)
    valid = rng.random((400, 4)) > 0.03
    valid[:7, 1] = False  # missing at the start
    valid[100:160, 2] = False  # a long gap
    valid[200:204, 0] = False  # a short one, back within the ramp, then lost again
    valid[208:212, 0] = False
    weight, source = engagement(valid, 100.0)
    disp = rng.normal(size=(400, 4, 3))
    disp[~valid] = np.nan
    causal = _Engagement(4, 100.0)
    for t in range(400):
        w, anchored = causal(disp[t])
        np.testing.assert_array_equal(w, weight[t])
        acting = w > 0
        np.testing.assert_array_equal(anchored[acting], disp[source[t], np.arange(4)][acting])


def test_no_rest_no_simulation(demo):
    names, positions, times, _ = demo
    sim = LiveSimulator(names, RunSettings(modes=20), rate=100.0)
    with pytest.raises(LiveSimulationError, match="no rest"):
        sim.step(positions[0])
    sim.observe(times[0], positions[0])
    with pytest.raises(LiveSimulationError, match="not enough frames"):
        sim.take_rest()
    tongue_missing = positions[:51].copy()
    tongue_missing[:, [names.index(n) for n in ("TT", "TD", "TL", "TR")]] = np.nan
    with pytest.raises(LiveSimulationError, match="cannot take this rest"):
        sim.set_rest(times[:51], tongue_missing)


def test_stillest_window_finds_the_still_part():
    times = np.arange(300) / 100.0
    positions = np.cumsum(np.random.default_rng(0).normal(size=(300, 2, 3)), axis=0)
    positions[120:180] = positions[120]  # still from 1.2 to 1.8 s
    window = stillest_window(times, positions, 0.5)
    assert 120 <= window.start and window.stop <= 181
    assert stillest_window(times[:10], positions[:10], 0.5) is None


def test_live_on_a_real_speaker_placed_at_the_adult_size_equals_the_replay():
    """The Opti-Speech speaker's coils would make a tongue 5 times the model's: live mode, like the replay,
    places the generic adult tongue with the rest sensors on its surface, and draws the same surface."""
    from tests.conftest import shared_file
    from tonguevis.sim.simulate import simulate

    rec = open_recording(shared_file("ema", "optispeech", "006_OSN12_Kah_nofb_natural_take2_HR.tsv"))
    positions, _, times = recording_frames(rec)
    keep = slice(0, 600)
    streamed = Recording(rate=rec.rate, times=times[keep],
                         sensors={n: positions[keep, k] / 1000.0 for k, n in enumerate(rec.sensor_names)},
                         metadata=dict(rec.metadata))
    settings = RunSettings(modes=40)
    sim = LiveSimulator(rec.sensor_names, settings, rate=rec.rate, dtype=np.float64)
    for i in range(300):
        sim.observe(times[i], positions[i])
    sim.take_rest()
    assert sim.fit["size_from"] == "adult norm" and sim.fit["tongue_size"] == 1.0
    live = np.array([sim.step(positions[i]).surface.copy() for i in range(600)])  # the buffer is reused
    rest = RestChoice((float(sim.rest_times[0]), float(sim.rest_times[-1])), "given")
    motion = simulate(streamed, settings, rest=rest)
    assert motion.metadata["fit"]["size_from"] == "adult norm"
    replay = motion.model.mesh.points[sim.surface_nodes][None] + motion.model.displacements(
        motion.q, nodes=sim.surface_nodes)
    assert np.abs(replay - replay[:1]).max() > 3e-3
    assert np.abs(live - replay).max() < 1e-9
