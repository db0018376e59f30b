"""Energy curves (§6.3): U = ½ qᵀΛq, cutting into productions, statistics, grouping."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tests.analysis.energy_support import MODES, box_tongue
from tonguevis.analysis.energy import (
    EnergyCurve,
    EnergyError,
    group_curves,
    modal_energy,
    production_curves,
    summarize,
)


def test_modal_energy_is_half_q_lambda_q():
    rng = np.random.default_rng(1)
    lam = rng.uniform(1.0, 100.0, 7)
    q = rng.normal(size=(5, 7))
    expected = [0.5 * qi @ np.diag(lam) @ qi for qi in q]
    np.testing.assert_allclose(modal_energy(q, lam), expected, rtol=1e-13)
    with pytest.raises(EnergyError, match="7 modes but 6 eigenvalues"):
        modal_energy(q, lam[:6])


def test_modal_energy_equals_strain_energy_of_linear_displacement():
    """With mass-normalised modes ½ qᵀΛq = ½ (Φq)ᵀ K (Φq): the energy is the FEM strain energy."""
    model = box_tongue()
    basis = model.basis(MODES)
    q = np.random.default_rng(2).normal(size=(3, MODES)) * 1e-3
    u = q @ basis.phi.T  # (3, 3n)
    strain = 0.5 * np.einsum("fi,fi->f", u, (model.stiffness @ u.T).T)
    np.testing.assert_allclose(modal_energy(q, basis.eigenvalues), strain, rtol=1e-8)
    np.testing.assert_allclose(model.energy(q), strain, rtol=1e-8)


def _motion(times, energy):
    return SimpleNamespace(times=np.asarray(times, float), energy=np.asarray(energy, float))


def test_production_curves_cut_and_normalise():
    times = np.arange(0, 2.0, 0.01)
    energy = np.sin(times) ** 2
    prods = [SimpleNamespace(train=1, index=2, start=0.205, end=0.505),
             SimpleNamespace(train=1, index=3, start=0.505, end=0.90)]
    curves = production_curves(_motion(times, energy), prods, recording="r", speaker="s", syllable="ta", trial=2)
    assert [c.production for c in curves] == ["1.2", "1.3"]
    first = curves[0]
    # Frames 0.21 .. 0.50 lie inside 0.205 .. 0.505.
    np.testing.assert_allclose(first.times, np.arange(21, 51) * 0.01, atol=1e-12)
    np.testing.assert_allclose(first.time_s, first.times - 0.205, atol=1e-12)
    np.testing.assert_allclose(first.time_norm, (first.times - 0.205) / 0.3, atol=1e-12)
    np.testing.assert_allclose(first.energy, np.sin(first.times) ** 2)
    assert (first.speaker, first.syllable, first.trial) == ("s", "ta", 2)
    assert np.all((first.time_norm >= 0) & (first.time_norm <= 1))


def test_production_outside_motion_is_an_error():
    times = np.arange(0, 1.0, 0.01)
    with pytest.raises(EnergyError, match="production 2.3"):
        production_curves(_motion(times, times), [SimpleNamespace(train=2, index=3, start=1.5, end=1.8)],
                          recording="x")


def _triangle(peak, at, duration=0.4, n=401, **labels):
    t = np.linspace(0, duration, n)
    e = np.where(t <= at, peak * t / at, peak * (duration - t) / (duration - at))
    base = dict(recording="r", speaker="s", syllable="ta", trial=1, train=1, index=2)
    base.update(labels)
    return EnergyCurve(**base, times=t + 5.0, time_s=t, time_norm=t / duration, energy=e,
                       frames=np.arange(n), start=5.0, end=5.0 + duration)


def test_stats_of_a_triangle():
    stats = _triangle(2e-3, 0.1).stats()
    assert stats["peak_J"] == pytest.approx(2e-3)
    assert stats["peak_time_s"] == pytest.approx(0.1)
    assert stats["peak_time_norm"] == pytest.approx(0.25)
    assert stats["area_Js"] == pytest.approx(0.5 * 0.4 * 2e-3, rel=1e-9)
    assert stats["duration_s"] == pytest.approx(0.4)


def test_grouping_and_summary():
    curves = [_triangle(1e-3, 0.1, speaker="a", syllable="ka"), _triangle(3e-3, 0.2, speaker="a", syllable="ka"),
              _triangle(5e-3, 0.1, speaker="b", syllable="ka"), _triangle(7e-3, 0.3, speaker="a", syllable="la")]
    groups = group_curves(curves, ("speaker", "syllable"))
    assert list(groups) == [("a", "ka"), ("b", "ka"), ("a", "la")]
    assert [len(v) for v in groups.values()] == [2, 1, 1]
    assert list(group_curves(curves, ("syllable",))) == [("ka",), ("la",)]
    summary = {g.key: g for g in summarize(curves)}
    ka = summary[("a", "ka")]
    assert ka.n == 2
    assert ka.mean["peak_J"] == pytest.approx(2e-3)
    assert ka.std["peak_J"] == pytest.approx(np.std([1e-3, 3e-3], ddof=1))
    assert ka.mean["peak_time_s"] == pytest.approx(0.15)
    np.testing.assert_allclose(ka.mean_curve, (curves[0].resampled() + curves[1].resampled()) / 2)
    assert summary[("b", "ka")].std["peak_J"] == 0.0
    with pytest.raises(EnergyError, match="unknown grouping key"):
        group_curves(curves, ("colour",))


def _skewed(scale, power, n, duration, **labels):
    """A curve whose samples have mean != median (a triangle's do not), on its own time grid."""
    t = np.linspace(0, duration, n)
    e = scale * (t / duration) ** power + 1e-5 * np.sin(7 * t)
    base = dict(recording="r", speaker="s", syllable="ta", trial=1, train=1, index=2)
    base.update(labels)
    return EnergyCurve(**base, times=t + 2.0, time_s=t, time_norm=t / duration, energy=e,
                       frames=np.arange(n), start=2.0, end=2.0 + duration)


def test_mean_energy_and_curve_spread_match_numpy():
    curves = [_skewed(4e-3, 3, 41, 0.3), _skewed(1e-3, 5, 57, 0.45), _skewed(2.5e-3, 2, 33, 0.25)]
    for c in curves:
        assert c.stats()["mean_J"] == pytest.approx(np.mean(c.energy), rel=1e-12)
        assert abs(np.mean(c.energy) - np.median(c.energy)) > 0.05 * np.mean(c.energy)  # the two differ here
    (group,) = summarize(curves, grid_points=51)
    grid = np.linspace(0.0, 1.0, 51)
    on_grid = np.array([np.interp(grid, c.time_norm, c.energy) for c in curves])
    np.testing.assert_allclose(group.grid, grid, rtol=0, atol=1e-15)
    np.testing.assert_allclose(group.mean_curve, on_grid.mean(axis=0), rtol=1e-12, atol=0)
    np.testing.assert_allclose(group.std_curve, on_grid.std(axis=0, ddof=1), rtol=1e-12, atol=1e-20)
    means = [np.mean(c.energy) for c in curves]
    assert group.mean["mean_J"] == pytest.approx(np.mean(means), rel=1e-12)
    assert group.std["mean_J"] == pytest.approx(np.std(means, ddof=1), rel=1e-12)


def test_vowel_windows_put_the_consonant_inside():
    from tonguevis.analysis.energy import vowel_windows

    prods = [SimpleNamespace(train=t, index=i, start=s, end=s + 0.3, release=s, vowel=s + 0.15)
             for t, base in ((1, 5.0), (2, 8.0)) for i, s in ((k, base + 0.3 * (k - 1)) for k in range(1, 6))]
    windows = vowel_windows(prods)
    assert [(w.train, w.index) for w in windows] == [(1, k) for k in range(2, 6)] + [(2, k) for k in range(2, 6)]
    first = windows[0]
    assert first.start == pytest.approx(5.15) and first.end == pytest.approx(5.45)
    assert first.start < first.release < first.end
    curves = production_curves(_motion(np.arange(0, 10, 0.01), np.ones(1000)), windows)
    assert curves[0].extra["release_s"] == pytest.approx(5.3)
