"""SMACOF (iterative majorisation): monotone stress, recovery of a known configuration."""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.analysis.mds import (
    MDSError,
    classical_mds,
    frame_dissimilarities,
    pairwise_distances,
    raw_stress,
    smacof,
)


def _procrustes_residual(a: np.ndarray, b: np.ndarray) -> float:
    """RMS distance between b and a after the best rotation/reflection + translation of a onto b."""
    a0, b0 = a - a.mean(0), b - b.mean(0)
    u, _, vt = np.linalg.svd(a0.T @ b0)
    return float(np.sqrt(np.mean(np.sum((a0 @ u @ vt - b0) ** 2, axis=1))))


def _reference_stress(x, delta, w=None):
    n = len(x)
    total = 0.0
    for i in range(n):
        for j in range(i + 1, n):
            wij = 1.0 if w is None else w[i, j]
            total += wij * (np.linalg.norm(x[i] - x[j]) - delta[i, j]) ** 2
    return total


def test_distances_and_stress_match_loops():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(9, 3))
    d = pairwise_distances(x)
    ref = np.array([[np.linalg.norm(a - b) for b in x] for a in x])
    np.testing.assert_allclose(d, ref, atol=1e-12)
    delta = ref + rng.uniform(0, 0.1, ref.shape)
    delta = 0.5 * (delta + delta.T)
    np.fill_diagonal(delta, 0)
    w = rng.uniform(0.5, 2, delta.shape)
    w = 0.5 * (w + w.T)
    assert raw_stress(x, delta) == pytest.approx(_reference_stress(x, delta))
    assert raw_stress(x, delta, w) == pytest.approx(_reference_stress(x, delta, w))


@pytest.mark.parametrize("weighted", [False, True])
def test_stress_never_increases_from_a_random_start(weighted):
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(40, 5))
    delta = pairwise_distances(pts)  # 5-D data into 2-D: a real residual stress
    w = None
    if weighted:
        w = rng.uniform(0.2, 1.0, delta.shape)
        w = 0.5 * (w + w.T)
    res = smacof(delta, 2, init="random", weights=w, max_iter=200, tol=0)
    steps = np.diff(res.stress_history)
    assert len(steps) == 200
    assert np.all(steps <= 1e-12 * res.stress_history[0])
    assert res.stress_history[-1] < 0.5 * res.stress_history[0]
    assert res.stress == pytest.approx(raw_stress(res.embedding, delta, w))


def test_recovers_a_known_configuration_up_to_rigid_motion():
    rng = np.random.default_rng(7)
    truth = rng.uniform(-1, 1, size=(30, 2))
    delta = pairwise_distances(truth)
    res = smacof(delta, 2, init="random", max_iter=3000, tol=1e-12)
    assert res.stress1 < 1e-4
    assert _procrustes_residual(res.embedding, truth) < 1e-3
    # Classical scaling alone is exact for Euclidean distances.
    assert _procrustes_residual(classical_mds(delta, 2), truth) < 1e-9


def test_frame_dissimilarities_are_mass_weighted_shape_distances():
    q = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 0.0]])
    np.testing.assert_allclose(frame_dissimilarities(q), [[0, 5, 3], [5, 0, 4], [3, 4, 0]])


def test_bad_input():
    with pytest.raises(MDSError, match="square"):
        smacof(np.zeros((3, 2)))
    d = np.array([[0, 1.0], [2.0, 0]])
    with pytest.raises(MDSError, match="symmetric"):
        smacof(d)
    with pytest.raises(MDSError, match="non-negative"):
        smacof(-np.ones((2, 2)))
    with pytest.raises(MDSError, match="init"):
        smacof(np.ones((3, 3)) - np.eye(3), init="spectral")
