"""The bar of Figs. 8-10: a bar whose middle is bent, segmented with rigid and
constraint modes, autoseeded with constrained ends, and adjusted."""

from __future__ import annotations

import numpy as np
import pytest

from tests.analysis.segmentation_support import bar_mesh, bent_bar_displacement, end_nodes, tet_containing_x
from tonguevis.analysis.segmentation import SegmentationTarget, TetGraph, make_fitter, segment
from tonguevis.analysis.segmentation.adjust import adjust_boundaries
from tonguevis.analysis.segmentation.evaluate import evaluate
from tonguevis.mesh.tetmesh import TetMesh

LENGTH, BEND_START, BEND_END = 0.12, 0.04, 0.08
CELL = LENGTH / 24


@pytest.fixture(scope="module")
def bent_bar():
    points, tets = bar_mesh(24, 2, 2, length=LENGTH)
    displacement = bent_bar_displacement(points, BEND_START, BEND_END, angle=0.5)
    return TetMesh(points, tets), SegmentationTarget.frame(displacement, description="bent bar")


def _three_seeds(mesh):
    return [tet_containing_x(mesh.points, mesh.tets, x) for x in (0.0, 0.5 * LENGTH, LENGTH)]


def _extent(mesh, labels, p):
    x = mesh.points[mesh.tets].mean(axis=1)[:, 0]
    return x[labels == p].min(), x[labels == p].max()


@pytest.mark.parametrize("mode", ["rigid", "constraint"])
def test_three_partitions_with_boundaries_at_the_bend(bent_bar, mode):
    """Fig. 8: left and right stay rigid pieces; the interfaces sit in or next to the bend."""
    mesh, target = bent_bar
    result = segment(mesh, target, mode, seeds=_three_seeds(mesh), constrained_nodes=[])
    assert result.n_partitions == 3
    left, middle, right = (_extent(mesh, result.labels, p) for p in range(3))
    # everything well left of the bend is in the left partition, and so on
    x = mesh.points[mesh.tets].mean(axis=1)[:, 0]
    assert np.all(result.labels[x < BEND_START - 2 * CELL] == 0)
    assert np.all(result.labels[x > BEND_END + 2 * CELL] == 2)
    # the middle partition lies inside the bend (give or take a cell)
    assert middle[0] >= BEND_START - 2 * CELL and middle[1] <= BEND_END + 2 * CELL
    # the interfaces are inside the bent region
    assert BEND_START - 2 * CELL <= left[1] <= BEND_END
    assert BEND_START <= right[0] <= BEND_END + 2 * CELL
    # three local fits do far better than one fit of the whole bar
    whole = segment(mesh, target, mode, seeds=[0], constrained_nodes=[])
    assert result.relative_error < 0.02 * whole.relative_error


def test_constraint_fit_equals_target_on_interfaces_rigid_does_not(bent_bar):
    mesh, target = bent_bar
    seeds = _three_seeds(mesh)
    ends = end_nodes(mesh.points)
    constraint = segment(mesh, target, "constraint", seeds=seeds, constrained_nodes=ends)
    rigid = segment(mesh, target, "rigid", seeds=seeds)
    u = target.displacements[0]
    graph = TetGraph.from_tets(mesh.tets, mesh.n_nodes)
    interface = np.unique(np.concatenate([graph.boundary_nodes(np.flatnonzero(constraint.labels == p))
                                          for p in range(3)]))
    assert len(interface) > 0
    # every partition's copy of an interface or constrained node equals the target
    on = np.isin(constraint.split_nodes, np.concatenate([interface, ends]))
    np.testing.assert_allclose(constraint.approximation[0][on], u[constraint.split_nodes[on]], atol=1e-15)
    assert constraint.interface_gap().max() < 1e-15
    # rigid pieces do not meet: their copies of interface nodes disagree
    scale = np.abs(u).max()
    assert rigid.interface_gap().max() > 1e-3 * scale
    rigid_interface = np.isin(rigid.split_nodes, np.unique(np.concatenate(
        [graph.boundary_nodes(np.flatnonzero(rigid.labels == p)) for p in range(3)])))
    assert np.abs(rigid.approximation[0][rigid_interface] - u[rigid.split_nodes[rigid_interface]]).max() > 1e-4 * scale


def test_autoseeding_with_constrained_ends(bent_bar):
    """Fig. 9: constrained ends; a new seed where the error is largest; the ends stay exact."""
    mesh, target = bent_bar
    ends = end_nodes(mesh.points)
    one = segment(mesh, target, "constraint", seeds="auto", n_partitions=1, constrained_nodes=ends, adjust=False)
    assert one.n_partitions == 1
    # with only the ends as boundary the bend is smeared over the whole bar: clearly worse than 1 %
    assert one.relative_error > 0.01
    worst = int(np.argmax(one.element_errors))
    result = segment(mesh, target, "constraint", seeds="auto", threshold=0.01, constrained_nodes=ends,
                     adjust=False)
    assert result.n_partitions >= 2
    assert result.relative_error <= 0.01
    assert worst in result.seeds.tolist()  # the first new seed is the worst element of one partition
    # the history records the autoseeding steps, ending at the result
    assert result.history[0, 0] == 1 and result.history[0, 1] == pytest.approx(one.relative_error)
    assert result.history[-1, 1] == pytest.approx(result.relative_error)
    assert np.all(result.history[1:, 1] < result.history[0, 1])
    approximation = result.nodal_approximation()[0]
    np.testing.assert_allclose(approximation[ends], target.displacements[0][ends], atol=1e-15)
    three = segment(mesh, target, "constraint", seeds="auto", n_partitions=3, threshold=None,
                    constrained_nodes=ends, adjust=False)
    assert three.n_partitions == 3 and three.relative_error < one.relative_error


@pytest.mark.parametrize("mode", ["rigid", "constraint"])
def test_post_adjustment_never_raises_the_global_error(bent_bar, mode):
    """Fig. 10: seeds put off-centre on purpose; each accepted move lowers e_G."""
    mesh, target = bent_bar
    seeds = [tet_containing_x(mesh.points, mesh.tets, x) for x in (0.0, 0.03, 0.11)]
    fitter = make_fitter(mesh.points, mesh.tets, target, mode, [])
    from tonguevis.analysis.segmentation.greedy import grow_partitions

    labels = grow_partitions(fitter, seeds)
    before = evaluate(fitter, labels)
    adjusted, trace = adjust_boundaries(fitter, labels, np.array(seeds), before.element_errors,
                                        max_evaluations=400)
    assert len(trace) > 1, "the adjustment made no move: the test would not test anything"
    assert np.all(np.diff(trace) < 0)
    after = evaluate(fitter, adjusted)
    volume = fitter.tet_volumes.sum()
    # the trace is the truth: a fresh evaluation of the final labels agrees with it
    assert after.global_error == pytest.approx(trace[-1] / volume, rel=1e-8)
    assert before.global_error == pytest.approx(trace[0] / volume, rel=1e-8)
    assert after.global_error < before.global_error
    # partitions stay face-connected and seeds stay in their partitions
    graph = fitter.graph
    for p in range(3):
        assert graph.is_connected(np.flatnonzero(adjusted == p))
        assert adjusted[seeds[p]] == p


def test_segment_runs_adjustment_and_records_it(bent_bar):
    mesh, target = bent_bar
    seeds = [tet_containing_x(mesh.points, mesh.tets, x) for x in (0.0, 0.03, 0.11)]
    plain = segment(mesh, target, "constraint", seeds=seeds, constrained_nodes=[])
    adjusted = segment(mesh, target, "constraint", seeds=seeds, constrained_nodes=[], adjust=True,
                       max_adjust_evaluations=100)
    assert adjusted.metadata["adjusted"] and not plain.metadata["adjusted"]
    assert adjusted.global_error < plain.global_error
    steps = adjusted.history[:, 1]
    assert np.all(np.diff(steps) < 0) and steps[-1] == pytest.approx(adjusted.relative_error, rel=1e-8)
