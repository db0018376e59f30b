"""Segmentation on the paper's tongue mesh (ArtiSynth, from ../shared; skipped without it)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import shared_file
from tonguevis.analysis.segmentation import SegmentationTarget, TetGraph, segment


@pytest.fixture(scope="module")
def tongue():
    from tonguevis.mesh.axes import ARTISYNTH_AXES
    from tonguevis.mesh.readers import read_mesh

    mesh = read_mesh(shared_file("artisynth", "tongue3.1.node"), axes=ARTISYNTH_AXES)
    p = mesh.points
    tip = p[np.argmax(p[:, 0])]
    # a tip raise fading towards the root, and a root that does not move at its floor
    near_tip = np.exp(-np.sum((p - tip) ** 2, axis=1) / 0.02**2)
    u = np.stack([-0.004 * near_tip, np.zeros(len(p)), 0.012 * near_tip], axis=1)
    anchors = np.argsort(p[:, 2] + 0.2 * (p[:, 0] - p[:, 0].max()))[:5]  # low and back
    u[anchors] = 0.0
    centres = p[mesh.tets].mean(axis=1)
    seeds = [int(np.argmin(np.sum((centres - q) ** 2, axis=1))) for q in (tip, p[anchors[0]], p.mean(axis=0))]
    return mesh, SegmentationTarget.frame(u, description="tip raise"), anchors, seeds


def test_constraint_modes_fit_the_tongue_far_better_than_rigid_ones(tongue):
    mesh, target, anchors, seeds = tongue
    rigid = segment(mesh, target, "rigid", seeds=seeds)
    constraint = segment(mesh, target, "constraint", seeds=seeds, constrained_nodes=anchors)
    graph = TetGraph.from_tets(mesh.tets, mesh.n_nodes)
    for result in (rigid, constraint):
        assert result.n_partitions == 3 and np.bincount(result.labels).min() > 0
        for p in range(3):
            assert graph.is_connected(np.flatnonzero(result.labels == p))
            assert result.labels[seeds[p]] == p
    assert constraint.relative_error < 0.2 * rigid.relative_error
    fitted = constraint.nodal_approximation()[0]
    np.testing.assert_allclose(fitted[anchors], 0.0, atol=1e-15)
    assert constraint.interface_gap().max() < 1e-12
    assert rigid.interface_gap().max() > 1e-4
