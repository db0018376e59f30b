"""warp-lang kernels for the per-node accumulated rotation of modal warping.

One thread per (frame, node): given the node's rotation vector w = (W q)_i and
linear displacement d = (Φ q)_i, write ũ_i = R̃(w) d without forming a 3×3
matrix.  The NumPy reference is :func:`tonguevis.sim.rotation.rotate_accumulated`;
a test proves them equal to 1e-10.  Runs on the CPU by default, on CUDA when a
GPU is present (``device=None`` picks warp's preferred device).
"""

from __future__ import annotations

import threading

import numpy as np

_lock = threading.Lock()
_kernel = None
_wp = None


def _build():
    global _kernel, _wp
    with _lock:
        if _kernel is not None:
            return
        import warp as wp

        wp.config.quiet = True
        wp.init()

        @wp.func
        def coefficients(t: wp.float64):
            t2 = t * t
            a = wp.float64(0.0)
            b = wp.float64(0.0)
            if t < wp.float64(0.05):
                a = wp.float64(0.5) - t2 / wp.float64(24.0) + t2 * t2 / wp.float64(720.0)
                b = wp.float64(1.0) / wp.float64(6.0) - t2 / wp.float64(120.0) + t2 * t2 / wp.float64(5040.0)
            else:
                a = (wp.float64(1.0) - wp.cos(t)) / t2
                b = (t - wp.sin(t)) / (t2 * t)
            return a, b

        @wp.kernel
        def warp_rotate(w: wp.array(dtype=wp.vec3d), d: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.vec3d)):
            i = wp.tid()
            wi = w[i]
            di = d[i]
            a, b = coefficients(wp.length(wi))
            wd = wp.cross(wi, di)
            out[i] = di + a * wd + b * wp.cross(wi, wd)

        _wp = wp
        _kernel = warp_rotate


def warp_device() -> str:
    """The device the kernels run on ("cpu" or "cuda:0")."""
    _build()
    return str(_wp.get_preferred_device())


def rotate_accumulated_warp(w: np.ndarray, d: np.ndarray, device: str | None = None) -> np.ndarray:
    """R̃(w) d for (..., 3) float64 arrays, computed by the warp kernel."""
    _build()
    wp = _wp
    shape = np.shape(d)
    w2 = np.ascontiguousarray(np.reshape(w, (-1, 3)), dtype=np.float64)
    d2 = np.ascontiguousarray(np.reshape(d, (-1, 3)), dtype=np.float64)
    if len(d2) == 0:
        return np.zeros(shape)
    dev = device or wp.get_preferred_device()
    wa = wp.array(w2, dtype=wp.vec3d, device=dev)
    da = wp.array(d2, dtype=wp.vec3d, device=dev)
    out = wp.empty(len(d2), dtype=wp.vec3d, device=dev)
    wp.launch(_kernel, dim=len(d2), inputs=[wa, da], outputs=[out], device=dev)
    return out.numpy().reshape(shape)
