"""Fused warp-lang kernel for morph frames: blend the two ends, then warp.

Φq and Wq are linear in q, so for the blend q(t) = (1 − t) q_s + t q_t the
linear displacement and the nodal rotation vector of every node are the same
blend of the two ends' (Φq_s, Φq_t) and (Wq_s, Wq_t).  One thread per
(frame, node) blends those four 3-vectors and applies the accumulated
rotation R̃(w) d = d + a(θ) w × d + b(θ) w × (w × d) (see
:mod:`tonguevis.sim.rotation`), writing float64 or float32 (for rendering).
The NumPy reference is :func:`tonguevis.analysis.morph.morph_displacements_reference`;
a test proves them equal.
"""

from __future__ import annotations

import threading

import numpy as np

_lock = threading.Lock()
_kernels: dict = {}
_wp = None


def _build():
    global _wp
    with _lock:
        if _kernels:
            return
        from tonguevis._backend import load_warp

        wp = load_warp()

        @wp.func
        def warped_blend(t: wp.float64, ls: wp.vec3d, lt: wp.vec3d, ws: wp.vec3d, wt: wp.vec3d):
            s = wp.float64(1.0) - t
            d = s * ls + t * lt
            w = s * ws + t * wt
            th = wp.length(w)
            t2 = th * th
            a = wp.float64(0.0)
            b = wp.float64(0.0)
            if th < wp.float64(0.05):  # series: no cancellation in 1 - cos and θ - sin
                a = wp.float64(0.5) - t2 / wp.float64(24.0) + t2 * t2 / wp.float64(720.0)
                b = wp.float64(1.0) / wp.float64(6.0) - t2 / wp.float64(120.0) + t2 * t2 / wp.float64(5040.0)
            else:
                a = (wp.float64(1.0) - wp.cos(th)) / t2
                b = (th - wp.sin(th)) / (t2 * th)
            wd = wp.cross(w, d)
            return d + a * wd + b * wp.cross(w, wd)

        @wp.kernel
        def morph64(ts: wp.array(dtype=wp.float64), ls: wp.array(dtype=wp.vec3d), lt: wp.array(dtype=wp.vec3d),
                    ws: wp.array(dtype=wp.vec3d), wt: wp.array(dtype=wp.vec3d), out: wp.array2d(dtype=wp.vec3d)):
            f, i = wp.tid()
            out[f, i] = warped_blend(ts[f], ls[i], lt[i], ws[i], wt[i])

        @wp.kernel
        def morph32(ts: wp.array(dtype=wp.float64), ls: wp.array(dtype=wp.vec3d), lt: wp.array(dtype=wp.vec3d),
                    ws: wp.array(dtype=wp.vec3d), wt: wp.array(dtype=wp.vec3d), out: wp.array2d(dtype=wp.vec3f)):
            f, i = wp.tid()
            u = warped_blend(ts[f], ls[i], lt[i], ws[i], wt[i])
            out[f, i] = wp.vec3f(wp.float32(u[0]), wp.float32(u[1]), wp.float32(u[2]))

        _kernels[np.dtype(np.float64)] = morph64
        _kernels[np.dtype(np.float32)] = morph32
        _wp = wp


class MorphKernel:
    """The two ends of a morph held on the warp device; :meth:`frames` evaluates many t at once.

    lin_s, lin_t : (n, 3) linear displacements Φq of source and target (m);
    rot_s, rot_t : (n, 3) nodal rotation vectors Wq (rad).
    """

    def __init__(self, lin_s, lin_t, rot_s, rot_t, device: str | None = None):
        _build()
        wp = _wp
        self.device = device or wp.get_preferred_device()
        self.n = len(lin_s)
        self._ends = [wp.array(np.ascontiguousarray(a, dtype=np.float64), dtype=wp.vec3d, device=self.device)
                      for a in (lin_s, lin_t, rot_s, rot_t)]
        self._out = {}

    def frames(self, ts, dtype=np.float64) -> np.ndarray:
        """(T, n, 3) warped displacements at blend parameters ``ts`` (T,), in ``dtype``.

        The returned array is a fresh copy unless the device is the CPU and the
        same (T, dtype) was asked before, in which case the buffer is reused
        (copy it if you keep it across calls).
        """
        wp = _wp
        dtype = np.dtype(dtype)
        if dtype not in _kernels:
            raise ValueError(f"morph frames come as float64 or float32, not {dtype}")
        ts = np.ascontiguousarray(np.atleast_1d(ts), dtype=np.float64)
        key = (len(ts), dtype)
        if key not in self._out:
            vec = wp.vec3d if dtype == np.float64 else wp.vec3f
            self._out = {key: wp.empty((len(ts), self.n), dtype=vec, device=self.device)}
        out = self._out[key]
        t_arr = wp.array(ts, dtype=wp.float64, device=self.device)
        wp.launch(_kernels[dtype], dim=(len(ts), self.n), inputs=[t_arr, *self._ends], outputs=[out],
                  device=self.device)
        return out.numpy().reshape(len(ts), self.n, 3)
