"""Matching the frames of two recordings and the per-node difference of their tongues."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tonguevis.analysis.compare import match_frames, node_distances
from tonguevis.errors import TonguevisError


def prods(*spans):
    return [SimpleNamespace(start=a, end=b) for a, b in spans]


def test_productions_line_up_by_normalised_time_whatever_the_rates():
    ta = np.arange(0, 3, 0.01)  # A speaks slowly: productions of 0.5 s
    tb = np.arange(0, 2, 0.01)  # B fast: 0.25 s
    m = match_frames(ta, tb, prods((1.0, 1.5), (1.5, 2.0)), prods((0.5, 0.75), (0.75, 1.0), (1.0, 1.25)))
    assert m.mode == "production" and set(m.production.tolist()) == {1, 2}
    # The middle of A's first production (1.25 s) meets the middle of B's first (0.625 s).
    k = int(np.flatnonzero(np.isclose(ta[m.frames_a], 1.25))[0])
    assert tb[m.frames_b[k]] == pytest.approx(0.625, abs=0.006) and m.phase[k] == pytest.approx(0.5)
    assert m.partner(int(m.frames_a[k])) == m.frames_b[k] and m.partner(10) is None  # 0.1 s: no production
    assert np.all(np.diff(tb[m.frames_b][m.production == 1]) >= 0)  # monotone within a production


def test_absolute_time_pairs_the_same_moments_and_stops_at_the_shorter():
    ta = np.arange(0, 3, 0.01)
    tb = np.arange(0, 2, 0.004)  # another rate
    m = match_frames(ta, tb, mode="absolute")
    np.testing.assert_allclose(tb[m.frames_b], ta[m.frames_a], atol=0.002)
    assert ta[m.frames_a].max() <= 2.0


def test_bad_requests_are_clear_errors():
    t = np.arange(0, 1, 0.01)
    with pytest.raises(TonguevisError, match="absolute time"):
        match_frames(t, t, prods(), prods((0.1, 0.2)))
    with pytest.raises(TonguevisError, match="mode"):
        match_frames(t, t, mode="sideways")


def test_node_distance_is_zero_for_the_same_motion_and_the_shift_for_a_shifted_one():
    from tests.sim._models import bar_model
    from tonguevis.sim.motion import Motion

    model = bar_model()
    m = 8
    rng = np.random.default_rng(0)
    q = rng.normal(size=(20, m)) * 1e-4
    def motion(qq):
        f = len(qq)
        return Motion(times=np.arange(f) / 100.0, q=qq, model=model, warping=False, sensor_names=[],
                      sensor_nodes=np.zeros(0, int), targets=np.zeros((f, 0, 3)), sensor_residual=np.zeros((f, 0)),
                      energy=np.zeros(f), volume_change=np.zeros(f), converged=np.ones(f, bool))
    a, b = motion(q), motion(q[::-1].copy())
    match = match_frames(a.times, b.times, mode="absolute")
    assert np.abs(node_distances(a, a, match)).max() == 0
    d = node_distances(a, b, match)
    expected = np.linalg.norm(a.displacements() - b.displacements(), axis=2)
    np.testing.assert_allclose(d, expected, atol=1e-15)
    other = bar_model(nx=6)
    with pytest.raises(TonguevisError, match="different tongue meshes"):
        node_distances(a, Motion(**{**b.__dict__, "model": other}), match)
