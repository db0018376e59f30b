"""The fast segmentation path (moments, CSR slots, memo, SVD columns, sparse LU)
equals plain reference implementations (explicit bases, dense solves, loops)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.analysis.segmentation_support import (
    bar_mesh,
    reference_constraint_fit,
    reference_error,
    reference_greedy,
    reference_one_ring,
    reference_rigid_fit,
)
from tests.jittered import jittered, volume_spread
from tonguevis.analysis.segmentation import SegmentationTarget, TetGraph, make_fitter
from tonguevis.analysis.segmentation.greedy import grow_partitions


def _wavy_frames(points: np.ndarray, n_frames: int, seed: int = 0) -> np.ndarray:
    """Smooth non-rigid displacements (no exactly rigid region, so no error ties)."""
    rng = np.random.default_rng(seed)
    x = points / np.ptp(points, axis=0).max()
    frames = []
    for _ in range(n_frames):
        a, b, c = rng.normal(size=(3, 3))
        frames.append(0.003 * np.stack([np.sin(3 * x @ a), np.cos(2 * x @ b), np.sin(4 * x @ c + 1)], axis=1))
    return np.array(frames)


@pytest.fixture(scope="module", params=["structured", "jittered"])
def small_bar(request):
    """A 5 x 2 x 2 bar; 'jittered' moves its nodes so tet volumes (and lumped weights) differ."""
    points, tets = bar_mesh(5, 2, 2, length=0.05)
    if request.param == "jittered":
        points = jittered(points, tets, 0.2, seed=3)
        assert volume_spread(points, tets) > 3
    rng = np.random.default_rng(1)
    # shuffle tet and node order so that nothing relies on the structured numbering
    node_order = rng.permutation(len(points))
    inverse = np.argsort(node_order)
    points = points[node_order]
    tets = inverse[tets][rng.permutation(len(tets))]
    return points, tets


def _random_connected_set(graph: TetGraph, size: int, rng) -> np.ndarray:
    members = {int(rng.integers(graph.n_tets))}
    while len(members) < size:
        around = graph.neighbours[list(members)].ravel()
        around = [int(t) for t in around if t >= 0 and int(t) not in members]
        members.add(around[int(rng.integers(len(around)))])
    return np.array(sorted(members))


def test_one_ring_and_boundary_match_plain_loops(small_bar):
    points, tets = small_bar
    graph = TetGraph.from_tets(tets, len(points))
    rng = np.random.default_rng(2)
    labels = np.full(len(tets), -1)
    members = _random_connected_set(graph, 12, rng)
    labels[members] = 0
    other = _random_connected_set(graph, 6, rng)
    labels[other[labels[other] < 0]] = 1
    assert graph.one_ring(members, labels).tolist() == reference_one_ring(tets, members, labels)
    outside_nodes = set(tets[np.setdiff1d(np.arange(len(tets)), members)].ravel().tolist())
    expected = sorted(set(tets[members].ravel().tolist()) & outside_nodes)
    assert graph.boundary_nodes(members).tolist() == expected


@pytest.mark.parametrize("mode", ["rigid", "constraint"])
def test_partition_errors_match_reference_on_random_sets(small_bar, mode):
    points, tets = small_bar
    frames = _wavy_frames(points, 4)
    energy = np.array([1.0, 3.0, 0.5, 2.0])
    target = SegmentationTarget.sequence(frames, energy)
    constrained = np.array([0, 7, 19]) if mode == "constraint" else None
    fitter = make_fitter(points, tets, target, mode, constrained)
    graph = fitter.graph
    rng = np.random.default_rng(3)
    if mode == "rigid":
        def fit(p, t, m, f):
            return reference_rigid_fit(p, t, m, f)
    else:
        def fit(p, t, m, f):
            return reference_constraint_fit(p, t, m, f, constrained)
    sizes = [1, 2, 5, 17, 40, len(tets) - 3]
    for size in sizes:
        members = _random_connected_set(graph, size, rng)
        expected = reference_error(points, tets, members, frames, target.weights, fit)
        assert fitter.error(members) == pytest.approx(expected, rel=1e-7, abs=1e-14 * expected + 1e-30)
        nodes, approx = fitter.approximate(members, frames)
        ref_nodes, ref_approx = fit(points, tets, members, frames)
        assert nodes.tolist() == ref_nodes.tolist()
        np.testing.assert_allclose(approx, ref_approx, rtol=0, atol=1e-9 * np.abs(frames).max())
    # the whole mesh: no interface, only the constrained nodes (or none: u~ = 0)
    everything = np.arange(len(tets))
    expected = reference_error(points, tets, everything, frames, target.weights, fit)
    assert fitter.error(everything) == pytest.approx(expected, rel=1e-6)


def test_unpinned_constraint_partition_matches_min_norm_reference(small_bar):
    """Two boundary nodes leave a rotation free: the fit is the minimum-norm one."""
    points, tets = small_bar
    frames = _wavy_frames(points, 1, seed=5)
    constrained = np.array([3, 11])
    target = SegmentationTarget.frame(frames[0])
    fitter = make_fitter(points, tets, target, "constraint", constrained)
    everything = np.arange(len(tets))
    nodes, approx = fitter.approximate(everything, frames)
    _, ref = reference_constraint_fit(points, tets, everything, frames, constrained)
    np.testing.assert_allclose(approx, ref, atol=1e-6 * np.abs(frames).max())
    np.testing.assert_allclose(approx[0, constrained], frames[0, constrained], atol=1e-15)


@pytest.mark.parametrize("mode", ["rigid", "constraint"])
def test_greedy_with_caching_equals_plain_greedy(small_bar, mode):
    points, tets = small_bar
    frames = _wavy_frames(points, 3, seed=7)
    energy = np.array([2.0, 1.0, 4.0])
    target = SegmentationTarget.sequence(frames, energy)
    constrained = np.array([0, 5]) if mode == "constraint" else None
    fitter = make_fitter(points, tets, target, mode, constrained)
    seeds = [0, len(tets) // 2, len(tets) - 1]
    labels = grow_partitions(fitter, seeds)
    if mode == "rigid":
        def fit(p, t, m, f):
            return reference_rigid_fit(p, t, m, f)
    else:
        def fit(p, t, m, f):
            return reference_constraint_fit(p, t, m, f, constrained)
    expected = reference_greedy(points, tets, seeds, frames, target.weights, fit)
    assert labels.tolist() == expected.tolist()


def test_target_columns_reproduce_weighted_frame_errors(small_bar):
    """Σ_f w_f ‖L u_f‖² = Σ_j ‖L y_j‖² for a linear map L (here: a random projection)."""
    points, _ = small_bar
    frames = _wavy_frames(points, 6, seed=9)
    frames[3] = 2 * frames[1] - frames[0]  # rank deficient on purpose
    energy = np.linspace(1, 2, 6)
    target = SegmentationTarget.sequence(frames, energy)
    assert target.columns.shape[0] == 5
    rng = np.random.default_rng(4)
    matrix = rng.normal(size=(3 * len(points), 3 * len(points)))
    direct = sum(w * np.sum((matrix @ u.ravel()) ** 2) for w, u in zip(target.weights, frames))
    reduced = sum(np.sum((matrix @ y.ravel()) ** 2) for y in target.columns)
    assert reduced == pytest.approx(direct, rel=1e-9)


def test_zero_boundary_shortcut_matches_a_real_solve(small_bar):
    """Whole mesh, boundary = constrained nodes where the target is zero (anchors): ũ = 0 without a solve."""
    points, tets = small_bar
    frames = _wavy_frames(points, 2, seed=11)
    constrained = np.array([0, 7, 19, 25])
    frames[:, constrained] = 0.0
    target = SegmentationTarget.sequence(frames, np.array([1.0, 2.0]))
    fitter = make_fitter(points, tets, target, "constraint", constrained)
    everything = np.arange(len(tets))

    def fit(p, t, m, f):
        return reference_constraint_fit(p, t, m, f, constrained)

    expected = reference_error(points, tets, everything, frames, target.weights, fit)
    assert fitter.error(everything) == pytest.approx(expected, rel=1e-9)
    assert fitter.n_factorisations == 0
    nodes, approx = fitter.approximate(everything, frames)
    np.testing.assert_allclose(approx, fit(points, tets, everything, frames)[1], atol=1e-15)


def test_local_connectivity_test_equals_the_global_search(small_bar):
    points, tets = small_bar
    graph = TetGraph.from_tets(tets, len(points))
    rng = np.random.default_rng(13)
    outcomes = set()
    for size in (2, 5, 12, 30, 60):
        for _ in range(6):
            members = _random_connected_set(graph, size, rng)
            inside = np.zeros(len(tets), dtype=bool)
            inside[members] = True
            for tet in members:
                expected = graph.is_connected(members[members != tet])
                assert graph.stays_connected_without(inside, int(tet)) == expected
                outcomes.add(expected)
    assert outcomes == {True, False}  # both answers were exercised


def test_smaller_internal_set_solved_through_a_cached_factorisation(small_bar):
    """A proposal that lost a few nodes reuses the bigger factorisation: same fit as a fresh one."""
    points, tets = small_bar
    frames = _wavy_frames(points, 5, seed=17)
    target = SegmentationTarget.sequence(frames, np.ones(5))
    constrained = np.array([0, 7, 19])
    fitter = make_fitter(points, tets, target, "constraint", constrained)
    everything = fitter.interior_nodes(np.arange(len(tets) - 6))
    fitter.system(everything)
    smaller = everything[[i for i in range(len(everything)) if i not in (3, 10)]]
    derived = fitter.system(smaller)
    assert fitter.n_factorisations == 1 and fitter.n_reused == 1 and not derived.direct
    fresh = make_fitter(points, tets, target, "constraint", constrained).system(smaller)
    assert fresh.direct
    np.testing.assert_allclose(derived.fit(frames), fresh.fit(frames), rtol=0, atol=1e-12 * np.abs(frames).max())
