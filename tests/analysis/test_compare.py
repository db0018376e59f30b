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


def bar_motion(q, model=None, rate=100.0):
    from tests.sim._models import bar_model
    from tonguevis.sim.motion import Motion

    f = len(q)
    return Motion(times=np.arange(f) / rate, q=q, model=model or bar_model(), warping=False, sensor_names=[],
                  sensor_nodes=np.zeros(0, int), targets=np.zeros((f, 0, 3)), sensor_residual=np.zeros((f, 0)),
                  energy=np.zeros(f), volume_change=np.zeros(f), converged=np.ones(f, bool))


def test_node_distance_is_zero_for_the_same_motion_and_the_shift_for_a_shifted_one():
    from tests.sim._models import bar_model
    from tonguevis.sim.motion import Motion

    rng = np.random.default_rng(0)
    q = rng.normal(size=(20, 8)) * 1e-4
    model = bar_model()
    a, b = bar_motion(q, model), bar_motion(q[::-1].copy(), model)
    match = match_frames(a.times, b.times, mode="absolute")
    assert np.abs(node_distances(a, a, match)).max() == 0
    d = node_distances(a, b, match)
    expected = np.linalg.norm(a.displacements() - b.displacements(), axis=2)
    np.testing.assert_allclose(d, expected, atol=1e-15)
    other = bar_model(nx=6)
    with pytest.raises(TonguevisError, match="different tongue meshes"):
        node_distances(a, Motion(**{**b.__dict__, "model": other}), match)


def test_comparison_time_map_pairs_the_frames_match_frames_pairs():
    """The continuous map the app uses gives, inside every production, the frames of the plain pairing."""
    from tonguevis.analysis.compare import Comparison

    rng = np.random.default_rng(1)
    a = bar_motion(rng.normal(size=(300, 8)) * 1e-4)            # 3 s at 100 Hz
    b = bar_motion(rng.normal(size=(500, 8)) * 1e-4, rate=250.0)  # 2 s at 250 Hz
    pa, pb = prods((1.0, 1.5), (1.5, 2.0), (2.2, 2.6)), prods((0.5, 0.75), (0.75, 1.0), (1.2, 1.3), (1.4, 1.9))
    c = Comparison(a, b, "production", pa, pb)
    m = match_frames(a.times, b.times, pa, pb)
    assert np.array_equal([c.frame_b(t) for t in a.times[m.frames_a]], m.frames_b)
    tb = c.time_b(a.times)
    assert np.all(np.diff(tb) >= 0) and tb.min() >= b.times[0] and tb.max() <= b.times[-1]
    assert c.time_b(0.9) == pytest.approx(0.4)  # before the first production: A's pace, from the first knot
    assert c.time_b(2.1) == pytest.approx(1.1)  # between productions 2 and 3: stretched like the gap
    assert c.phase(1.25) == (1, pytest.approx(0.5)) and c.phase(0.2) is None
    absolute = Comparison(a, b, "absolute")
    assert absolute.time_b(0.5) == pytest.approx(0.5) and absolute.time_b(2.9) == pytest.approx(b.times[-1])
    assert absolute.phase(1.25) is None


def test_comparison_difference_is_the_node_distance_and_needs_one_mesh():
    from tests.sim._models import bar_model
    from tonguevis.analysis.compare import Comparison

    rng = np.random.default_rng(2)
    model = bar_model()
    a, b = bar_motion(rng.normal(size=(30, 8)) * 1e-4, model), bar_motion(rng.normal(size=(40, 8)) * 1e-4, model)
    c = Comparison(a, b, "absolute")
    nodes = np.array([0, 5, 17])
    expected = np.linalg.norm(a.displacements()[7] - b.displacements()[12], axis=1)
    np.testing.assert_allclose(c.difference(7, 12), expected, rtol=1e-12, atol=0)
    np.testing.assert_allclose(c.difference(7, 12, nodes), expected[nodes], rtol=1e-12, atol=0)
    assert c.same_mesh and not Comparison(a, bar_motion(b.q, bar_model(nx=6)), "absolute").same_mesh
    with pytest.raises(TonguevisError, match="different tongue meshes"):
        Comparison(a, bar_motion(b.q, bar_model(nx=6)), "absolute").difference(0, 0)
    with pytest.raises(TonguevisError, match="absolute time"):
        Comparison(a, b, "production", prods(), prods((0.1, 0.2)))
