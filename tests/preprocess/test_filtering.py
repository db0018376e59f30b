"""Savitzky-Golay smoothing (NaN-aware) and derivatives against references and analytic signals."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.signal import savgol_filter

from tests.preprocess._synthetic import recording
from tonguevis.errors import TonguevisError
from tonguevis.preprocess import derivative, smooth
from tonguevis.preprocess._localpoly import savgol


def reference_savgol(y: np.ndarray, window: int, order: int, deriv: int = 0, delta: float = 1.0):
    """Plain loop: polyfit on the valid samples of each window, evaluated at the centre."""
    half = window // 2
    out = np.full(len(y), np.nan)
    for i in range(len(y)):
        if not np.isfinite(y[i]):
            continue
        k = np.arange(max(0, i - half), min(len(y), i + half + 1))
        k = k[np.isfinite(y[k])]
        if len(k) < order + 1:
            continue
        coeffs = np.polyfit((k - i) * delta, y[k], order)
        out[i] = np.polyval(np.polyder(coeffs, deriv), 0.0) if deriv else np.polyval(coeffs, 0.0)
    return out


def test_interior_equals_scipy_savgol():
    rng = np.random.default_rng(1)
    y = rng.normal(size=200)
    ours = savgol(y, 21, 3)
    theirs = savgol_filter(y, 21, 3)
    np.testing.assert_allclose(ours[10:-10], theirs[10:-10], atol=1e-12)
    d_ours = savgol(y, 11, 3, deriv=1, delta=0.01)
    d_theirs = savgol_filter(y, 11, 3, deriv=1, delta=0.01)
    np.testing.assert_allclose(d_ours[5:-5], d_theirs[5:-5], atol=1e-9)


@pytest.mark.parametrize("deriv", [0, 1, 2])
def test_nan_aware_equals_reference_loop(deriv):
    rng = np.random.default_rng(2)
    y = np.cumsum(rng.normal(size=150))
    y[[0, 17, 18, 19, 60, 61, 100, 149]] = np.nan
    y[30:45] = np.nan  # a gap longer than half the window
    ours = savgol(y, 9, 3, deriv=deriv, delta=0.01)
    ref = reference_savgol(y, 9, 3, deriv=deriv, delta=0.01)
    np.testing.assert_array_equal(np.isnan(ours), np.isnan(ref))
    np.testing.assert_allclose(ours, ref, rtol=1e-7, atol=1e-7)


def test_smooth_keeps_cubics_and_nan():
    t = np.arange(120) / 100.0
    cubic = 0.01 + 0.2 * t - 0.3 * t**2 + 0.1 * t**3
    xyz = np.column_stack([cubic, 2 * cubic, -cubic])
    xyz[50] = np.nan
    rec = recording({"TT": xyz, "JAW": xyz + 1.0})
    before = xyz.copy()
    out = smooth(rec, window=21, order=3)
    ok = np.isfinite(xyz[:, 0])
    np.testing.assert_allclose(out.sensors["TT"][ok], xyz[ok], atol=1e-12)  # edges too
    assert np.all(np.isnan(out.sensors["TT"][50]))
    assert out.metadata["smoothed"] == {"window": 21, "order": 3}
    np.testing.assert_array_equal(rec.sensors["TT"], before)  # the input is not modified


def test_smooth_reduces_noise():
    rng = np.random.default_rng(3)
    t = np.arange(1000) / 100.0
    clean = np.column_stack([np.sin(2 * np.pi * 1.0 * t)] * 3) * 0.005
    rec = recording({"TT": clean + rng.normal(0, 2e-4, clean.shape)})
    err_before = np.std(rec.sensors["TT"] - clean)
    err_after = np.std(smooth(rec).sensors["TT"] - clean)
    assert err_after < 0.4 * err_before


@pytest.mark.parametrize("window", [None, 11])
def test_derivatives_of_a_sine(window):
    rate, f, a = 100.0, 2.0, 0.01
    t = np.arange(400) / rate
    w = 2 * np.pi * f
    xyz = np.column_stack([a * np.sin(w * t), a * np.cos(w * t), np.full_like(t, 0.02)])
    rec = recording({"TT": xyz}, rate=rate)
    v = derivative(rec, 1, window=window)["TT"]
    acc = derivative(rec, 2, window=window)["TT"]
    inner = slice(10, -10)
    # central differences: relative error ~ (w h)^2 / 6 = 0.26 % for f = 2 Hz at 100 Hz
    np.testing.assert_allclose(v[inner, 0], a * w * np.cos(w * t[inner]), atol=0.01 * a * w)
    np.testing.assert_allclose(v[inner, 1], -a * w * np.sin(w * t[inner]), atol=0.01 * a * w)
    # a cubic over 11 frames (0.1 s) attenuates a 2 Hz acceleration by ~3 %
    tolerance = 0.02 if window is None else 0.05
    np.testing.assert_allclose(acc[inner, 0], -a * w**2 * np.sin(w * t[inner]), atol=tolerance * a * w**2)
    np.testing.assert_allclose(v[:, 2], 0.0, atol=1e-12)


def test_derivative_of_polynomial_is_exact_with_savgol():
    t = np.arange(50) / 100.0
    xyz = np.column_stack([t**2, t**3, t])
    rec = recording({"TT": xyz})
    v = derivative(rec, 1, window=7)["TT"]
    np.testing.assert_allclose(v, np.column_stack([2 * t, 3 * t**2, np.ones_like(t)]), atol=1e-9)


def test_bad_parameters_raise():
    rec = recording({"TT": np.zeros((30, 3))})
    with pytest.raises(TonguevisError, match="odd"):
        smooth(rec, window=20)
    with pytest.raises(TonguevisError, match="order"):
        smooth(rec, window=5, order=5)
    with pytest.raises(TonguevisError, match="must be 1"):
        derivative(rec, 3)
    with pytest.raises(TonguevisError, match="no sensor"):
        smooth(rec, sensors=["TD"])


@settings(max_examples=60, deadline=None)
@given(
    data=st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=3, max_size=60),
    mask_seed=st.integers(0, 2**16),
    half=st.integers(1, 6),
    order=st.integers(0, 4),
    deriv=st.integers(0, 2),
)
def test_nan_aware_savgol_property(data, mask_seed, half, order, deriv):
    """Any data, any gaps, any window/order: the batched fit equals the per-sample loop."""
    window = 2 * half + 1
    assume(order < window and deriv <= order)
    y = np.array(data)
    y[np.random.default_rng(mask_seed).random(len(y)) < 0.25] = np.nan
    ours = savgol(y, window, order, deriv=deriv, delta=0.01)
    ref = reference_savgol(y, window, order, deriv=deriv, delta=0.01)
    np.testing.assert_array_equal(np.isnan(ours), np.isnan(ref))
    scale = (np.nanmax(np.abs(y)) if np.isfinite(y).any() else 1.0) + 1.0
    np.testing.assert_allclose(ours, ref, atol=1e-6 * scale / 0.01**deriv, rtol=1e-6)


def test_savitzky_golay_of_a_long_recording_in_blocks_is_the_same_to_the_bit(monkeypatch):
    """A long recording is fitted in blocks with half a window of overlap: the same values, gaps and ends included."""
    import tonguevis.preprocess._localpoly as lp

    rng = np.random.default_rng(0)
    x = np.cumsum(rng.normal(size=(5000, 4, 3)), axis=0)
    x[rng.random(x.shape[:2]) < 0.02] = np.nan
    x[100:140] = np.nan
    whole = lp.local_polynomial(x, 21, 3, 2)
    monkeypatch.setattr(lp, "BLOCK_SAMPLES", 700)  # 700 does not divide 5000
    assert np.array_equal(lp.local_polynomial(x, 21, 3, 2), whole, equal_nan=True)
