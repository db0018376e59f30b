"""Each sensor gets its own node (prepare_targets' "speaker" landmarks): an assignment, not a nearest each."""

from __future__ import annotations

import itertools
import logging

import numpy as np
import pytest

from tests.conftest import shared_file
from tonguevis.preprocess.targets import assign_sensor_nodes


def _brute_force(positions, points, candidates):
    """The reference: every one-to-one choice over all candidates, least summed squared distance."""
    best, best_cost = None, np.inf
    for choice in itertools.permutations(candidates.tolist(), len(positions)):
        cost = float(np.sum((points[list(choice)] - positions) ** 2))
        if cost < best_cost:
            best, best_cost = np.array(choice), cost
    return best


def test_two_sensors_nearest_one_node_get_two_nodes():
    """Two sensors 1 mm apart straddle node 0, nearest to both: one keeps it, the other takes the next."""
    points = np.array([[0.0, 0.0, 0.0], [0.004, 0.0, 0.0], [-0.005, 0.0, 0.0], [0.0, 0.02, 0.0]])
    positions = np.array([[0.0005, 0.0, 0.0], [-0.0005, 0.0, 0.0]])
    nearest = np.argmin(np.linalg.norm(points[None] - positions[:, None], axis=2), axis=1)
    assert nearest.tolist() == [0, 0]  # the old nearest-node-each rule: one node for two sensors
    nodes = assign_sensor_nodes(positions, points, np.arange(4))
    assert nodes.tolist() == [1, 0]  # the +x sensor moves to the +x node (3.5 mm) rather than the -x one to 4.5 mm
    assert len(set(nodes.tolist())) == 2


def test_a_sensor_with_its_own_nearest_node_keeps_it():
    rng = np.random.default_rng(3)
    points = rng.uniform(-0.03, 0.03, (200, 3))
    candidates = np.arange(0, 200, 2)
    positions = points[candidates[[5, 40, 77]]] + 1e-4
    np.testing.assert_array_equal(assign_sensor_nodes(positions, points, candidates), candidates[[5, 40, 77]])


@pytest.mark.parametrize("seed", range(6))
def test_assignment_equals_the_brute_force_reference(seed):
    """The fast path (a pool of each sensor's nearest candidates) gives the exhaustive optimum."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-0.01, 0.01, (9, 3))
    candidates = rng.permutation(9)[:7]
    positions = points[candidates[rng.integers(0, 7, 3)]] + rng.normal(0, 1e-3, (3, 3))  # often colliding
    fast = assign_sensor_nodes(positions, points, candidates)
    slow = _brute_force(positions, points, candidates)
    cost = lambda nodes: np.sum((points[nodes] - positions) ** 2)  # noqa: E731
    assert cost(fast) == pytest.approx(cost(slow), rel=1e-12)
    assert len(set(fast.tolist())) == 3 and set(fast.tolist()) <= set(candidates.tolist())


def test_too_few_candidates_is_a_clear_error():
    from tonguevis.errors import SimulationError

    with pytest.raises(SimulationError, match="3 sensors need as many distinct surface nodes"):
        assign_sensor_nodes(np.zeros((3, 3)), np.zeros((2, 3)), np.arange(2))


def test_artisynth_tongue_with_a_real_recording_gets_distinct_nodes(caplog):
    """The case of issue 27: ArtiSynth's tongue in its own frame, a real /ta/, default landmarks.

    Nearest-node-each put TT and TL on one node and TB and TR on another
    ("two sensors snapped to the same node"); now every sensor has its own.
    """
    from tonguevis.io import read_recording
    from tonguevis.mesh import find_landmarks, read_mesh
    from tonguevis.preprocess.targets import prepare_targets
    from tonguevis.sim.model import TongueModel

    mesh = read_mesh(shared_file("artisynth", "tongue3.1.node"))  # its own frame, on purpose
    model = TongueModel(mesh, find_landmarks(mesh))
    recording = read_recording(shared_file("ema", "optispeech", "009_OSN12_Tah_withFb_natural_HR.tsv"))
    with caplog.at_level(logging.ERROR):
        targets = prepare_targets(recording, model, landmarks="speaker")
    assert targets.names == ["TT", "TB", "TD", "TL", "TR"]
    assert len(set(targets.nodes.tolist())) == 5


@pytest.mark.timeout(300)
def test_artisynth_tongue_with_found_axes_simulates_a_real_recording_plausibly():
    """Axes found from the shape, default landmarks, real /ta/: volume 0.35 %, amplification 1.21 (measured)."""
    from tonguevis.io import read_recording
    from tonguevis.sim.model import TongueModel
    from tonguevis.sim.simulate import simulate

    model = TongueModel.from_mesh(shared_file("artisynth", "tongue3.1.node"), axes="auto")
    recording = read_recording(shared_file("ema", "optispeech", "009_OSN12_Tah_withFb_natural_HR.tsv"))
    motion = simulate(recording, model)
    figures = motion.metadata["plausibility"]
    assert figures["volume_change_max_percent"] < 1.0
    assert 0.8 < figures["amplification"] < 1.5
    assert len(set(np.asarray(motion.sensor_nodes).tolist())) == 5
