"""Accumulated nodal rotation of modal warping, NumPy reference implementation.

R̃(w) = I + a(θ) [w]× + b(θ) [w]×²,  θ = |w|,
a = (1 - cos θ)/θ²,  b = (θ - sin θ)/θ³,

which is ∫₀¹ R(s w) ds: the rotation R(s w) integrated along the straight path
from 0 to w in modal space (Choi & Ko 2005).  It depends on the current
rotation vector only (no history).  ``R̃ d = d + a (w × d) + b w × (w × d)``
never needs a 3×3 matrix.  The warp-lang kernels in :mod:`tonguevis.sim.kernels` compute
the same thing and are tested equal to this module.
"""

from __future__ import annotations

import numpy as np

_SMALL = 0.05  # below this θ (rad) the series are exact to double precision


def rotation_coefficients(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """a, b and their radial derivatives a'/θ, b'/θ for angles ``theta`` (rad).

    Series for small θ avoid the cancellation of 1 - cos θ and θ - sin θ.
    """
    t = np.asarray(theta, dtype=np.float64)
    t2 = t * t
    small = t < _SMALL
    ts = np.where(small, 1.0, t)  # safe divisor
    s, c = np.sin(ts), np.cos(ts)
    a = np.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, (1.0 - c) / ts**2)
    b = np.where(small, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0, (ts - s) / ts**3)
    da = np.where(small, -1.0 / 12.0 + t2 / 180.0 - t2 * t2 / 6720.0, (ts * s - 2.0 * (1.0 - c)) / ts**4)
    db = np.where(
        small, -1.0 / 60.0 + t2 / 1260.0 - t2 * t2 / 60480.0, ((1.0 - c) * ts - 3.0 * (ts - s)) / ts**5
    )
    return a, b, da, db


def accumulated_rotation_matrix(w: np.ndarray) -> np.ndarray:
    """(..., 3, 3) R̃(w) for rotation vectors ``w`` (..., 3); for tests and small use."""
    w = np.asarray(w, dtype=np.float64)
    a, b, _, _ = rotation_coefficients(np.linalg.norm(w, axis=-1))
    z = np.zeros(w.shape[:-1])
    wx = np.stack(
        [
            np.stack([z, -w[..., 2], w[..., 1]], -1),
            np.stack([w[..., 2], z, -w[..., 0]], -1),
            np.stack([-w[..., 1], w[..., 0], z], -1),
        ],
        -2,
    )
    eye = np.broadcast_to(np.eye(3), wx.shape)
    return eye + a[..., None, None] * wx + b[..., None, None] * (wx @ wx)


def rotate_accumulated(w: np.ndarray, d: np.ndarray) -> np.ndarray:
    """R̃(w) d for arrays of rotation vectors and vectors, both (..., 3)."""
    a, b, _, _ = rotation_coefficients(np.linalg.norm(w, axis=-1))
    wd = np.cross(w, d)
    return d + a[..., None] * wd + b[..., None] * np.cross(w, wd)


def rotate_accumulated_jacobian(w: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Value and partial derivatives of g(w, d) = R̃(w) d.

    Returns g (..., 3), ∂g/∂d = R̃(w) (..., 3, 3) and ∂g/∂w (..., 3, 3):
    ∂g/∂w = (a'/θ)(w×d) wᵀ - a [d]× + (b'/θ)(w×(w×d)) wᵀ + b ((w·d) I + w dᵀ - 2 d wᵀ).
    """
    w = np.asarray(w, dtype=np.float64)
    d = np.asarray(d, dtype=np.float64)
    a, b, da, db = rotation_coefficients(np.linalg.norm(w, axis=-1))
    wd = np.cross(w, d)
    wwd = np.cross(w, wd)
    g = d + a[..., None] * wd + b[..., None] * wwd
    rot = accumulated_rotation_matrix(w)
    z = np.zeros(d.shape[:-1])
    dx = np.stack(
        [
            np.stack([z, -d[..., 2], d[..., 1]], -1),
            np.stack([d[..., 2], z, -d[..., 0]], -1),
            np.stack([-d[..., 1], d[..., 0], z], -1),
        ],
        -2,
    )
    outer = lambda x, y: x[..., :, None] * y[..., None, :]  # noqa: E731
    wdot = np.einsum("...i,...i->...", w, d)[..., None, None]
    dg_dw = (
        da[..., None, None] * outer(wd, w)
        - a[..., None, None] * dx
        + db[..., None, None] * outer(wwd, w)
        + b[..., None, None] * (wdot * np.eye(3) + outer(w, d) - 2.0 * outer(d, w))
    )
    return g, rot, dg_dw
