"""NaN-aware Savitzky-Golay: a least-squares polynomial fitted around every sample.

A Savitzky-Golay filter is the value (or a derivative) at the centre of a
polynomial fitted by least squares to a window of samples.  Here invalid
samples get weight zero and so do samples beyond the ends, so one formula
handles gaps and edges; where every sample of the window is valid it equals
:func:`scipy.signal.savgol_filter` exactly.  All windows are fitted at once:
the normal equations come from correlations of the validity mask and the data
with powers of the window offset (no loop over samples).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import correlate1d

from tonguevis.errors import TonguevisError


def check_window(window: int, order: int) -> None:
    if int(window) != window or window < 3 or window % 2 == 0:
        raise TonguevisError(f"Savitzky-Golay window must be an odd integer >= 3, got {window}")
    if int(order) != order or order < 0 or order >= window:
        raise TonguevisError(f"Savitzky-Golay order must be an integer in [0, window), got {order}")


#: Samples fitted at once: each window needs only its neighbours, so a long recording is taken in
#: blocks (with half a window of overlap) and its temporaries stay a few tens of MB (30 minutes of
#: four sensors at once took 0.5 GB); the result is the same to the last bit.
BLOCK_SAMPLES = 16384


def local_polynomial(values: np.ndarray, window: int, order: int, n_coefficients: int) -> np.ndarray:
    """Coefficients of the local polynomial fitted around every sample.

    values : (N, ...) float, NaN where invalid; axis 0 is time.
    window : odd number of samples in each fit; order : polynomial degree.
    Returns (n_coefficients, N, ...) float64: coefficient j multiplies
    ``(k / half)**j`` with k the offset in samples from the centre and
    ``half = window // 2`` (offsets scaled to [-1, 1] keep the normal equations
    well conditioned).  NaN where the sample itself is invalid or the window
    holds fewer than ``order + 1`` valid samples.
    """
    check_window(window, order)
    values = np.asarray(values, dtype=np.float64)
    n, half = values.shape[0], window // 2
    if n <= BLOCK_SAMPLES:
        return _local_polynomial(values, window, order, n_coefficients)
    out = np.empty((n_coefficients,) + values.shape)
    for start in range(0, n, BLOCK_SAMPLES):
        stop = min(start + BLOCK_SAMPLES, n)
        lo, hi = max(0, start - half), min(n, stop + half)  # the neighbours the block's windows reach
        out[:, start:stop] = _local_polynomial(values[lo:hi], window, order, n_coefficients)[:, start - lo:stop - lo]
    return out


def _local_polynomial(values: np.ndarray, window: int, order: int, n_coefficients: int) -> np.ndarray:
    """:func:`local_polynomial` of all the samples at once."""
    n = values.shape[0]
    flat = values.reshape(n, -1)
    valid = np.isfinite(flat)
    weights = valid.astype(np.float64)
    data = np.where(valid, flat, 0.0)
    half = window // 2
    offsets = np.arange(-half, half + 1) / half
    p = order + 1
    # moments[j] = sum_k w[n+k] (k/half)^j ; rhs[j] = sum_k w[n+k] y[n+k] (k/half)^j
    moments = np.stack([correlate1d(weights, offsets**j, axis=0, mode="constant") for j in range(2 * p - 1)])
    rhs = np.stack([correlate1d(data, offsets**j, axis=0, mode="constant") for j in range(p)])
    normal = moments[np.add.outer(np.arange(p), np.arange(p))]  # (p, p, N, M)
    normal = np.moveaxis(normal, (0, 1), (-2, -1))  # (N, M, p, p)
    count = moments[0]
    usable = (count >= p - 0.5) & valid
    # Unusable windows get the identity so one batched solve serves all; masked after.
    normal = np.where(usable[..., None, None], normal, np.eye(p))
    coeffs = np.linalg.solve(normal, np.moveaxis(rhs, 0, -1)[..., None])[..., 0]  # (N, M, p)
    coeffs = np.where(usable[..., None], coeffs, np.nan)
    coeffs = np.moveaxis(coeffs, -1, 0)[:n_coefficients]
    return coeffs.reshape((n_coefficients,) + values.shape)


def savgol(values: np.ndarray, window: int, order: int, deriv: int = 0, delta: float = 1.0) -> np.ndarray:
    """NaN-aware Savitzky-Golay value (deriv=0) or derivative along axis 0.

    values : (N, ...) samples spaced ``delta`` apart (seconds).  Returns an
    array of the same shape in units of values / delta**deriv, NaN where the
    input is NaN or too few valid neighbours exist.
    """
    if deriv > order:
        raise TonguevisError(f"derivative {deriv} needs a polynomial order >= {deriv}, got {order}")
    coeffs = local_polynomial(values, window, order, deriv + 1)
    half = window // 2
    factorial = float(np.prod(np.arange(1, deriv + 1))) if deriv else 1.0
    return coeffs[deriv] * factorial / (half * delta) ** deriv
