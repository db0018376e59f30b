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
_flux_kernel = None
_wp = None


def _build():
    global _kernel, _wp
    with _lock:
        if _kernel is not None:
            return
        from tonguevis._backend import load_warp

        wp = load_warp()

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

        @wp.kernel
        def warp_rotate32(w: wp.array(dtype=wp.vec3f), d: wp.array(dtype=wp.vec3f), out: wp.array(dtype=wp.vec3f)):
            # Rendering precision: coefficients in float64, vectors in float32.
            i = wp.tid()
            wi = wp.vec3d(w[i])
            di = wp.vec3d(d[i])
            a, b = coefficients(wp.length(wi))
            wd = wp.cross(wi, di)
            out[i] = wp.vec3f(di + a * wd + b * wp.cross(wi, wd))

        @wp.kernel
        def surface_flux(points: wp.array2d(dtype=wp.vec3d), faces: wp.array2d(dtype=int),
                         out: wp.array(dtype=wp.float64)):
            # Volume of a closed surface = Σ_faces p0 · (p1 × p2) / 6, one (frame, face) per thread.
            f, k = wp.tid()
            p0 = points[f, faces[k, 0]]
            p1 = points[f, faces[k, 1]]
            p2 = points[f, faces[k, 2]]
            wp.atomic_add(out, f, wp.dot(p0, wp.cross(p1, p2)) / wp.float64(6.0))

        global _flux_kernel
        _flux_kernel = surface_flux
        _wp = wp
        _kernel = {np.dtype(np.float64): (warp_rotate, wp.vec3d), np.dtype(np.float32): (warp_rotate32, wp.vec3f)}


def warp_device() -> str:
    """The device the kernels run on ("cpu" or "cuda:0")."""
    _build()
    return str(_wp.get_preferred_device())


def rotate_accumulated_compiled(w: np.ndarray, d: np.ndarray, device: str | None = None) -> np.ndarray:
    """R̃(w) d for (..., 3) arrays, computed by the warp kernel.

    float32 inputs (both) stay float32 (for rendering); anything else is float64.
    """
    _build()
    wp = _wp
    shape = np.shape(d)
    dtype = np.dtype(np.float32) if np.asarray(d).dtype == np.float32 and np.asarray(w).dtype == np.float32 else np.dtype(np.float64)
    kernel, vec = _kernel[dtype]
    w2 = np.ascontiguousarray(np.reshape(w, (-1, 3)), dtype=dtype)
    d2 = np.ascontiguousarray(np.reshape(d, (-1, 3)), dtype=dtype)
    if len(d2) == 0:
        return np.zeros(shape, dtype=dtype)
    dev = device or wp.get_preferred_device()
    on_cpu = str(dev) == "cpu"
    # On the CPU warp can wrap NumPy memory without copying.
    wa = wp.array(w2, dtype=vec, device=dev, copy=not on_cpu)
    da = wp.array(d2, dtype=vec, device=dev, copy=not on_cpu)
    out_np = np.empty_like(d2)
    out = wp.array(out_np, dtype=vec, device=dev, copy=False) if on_cpu else wp.empty(len(d2), dtype=vec, device=dev)
    wp.launch(kernel, dim=len(d2), inputs=[wa, da], outputs=[out], device=dev)
    if on_cpu:
        wp.synchronize_device(dev)
        return out_np.reshape(shape)
    return out.numpy().reshape(shape)


def enclosed_volumes(points: np.ndarray, faces: np.ndarray, device: str | None = None) -> np.ndarray:
    """(F,) volumes in m³ enclosed by the closed, outward surface ``faces`` (f, 3)
    for node positions ``points`` (F, n, 3): the warp-lang form of
    ⅙ Σ p0 · (p1 × p2) (NumPy reference: :meth:`TongueModel.volume_change` with
    ``backend="numpy"``)."""
    _build()
    wp = _wp
    pts = np.ascontiguousarray(points, dtype=np.float64)
    n_frames = pts.shape[0]
    dev = device or wp.get_preferred_device()
    pa = wp.array(pts.reshape(n_frames, -1, 3), dtype=wp.vec3d, device=dev)
    fa = wp.array(np.ascontiguousarray(faces, dtype=np.int32), dtype=wp.int32, device=dev)
    out = wp.zeros(n_frames, dtype=wp.float64, device=dev)
    wp.launch(_flux_kernel, dim=(n_frames, len(faces)), inputs=[pa, fa], outputs=[out], device=dev)
    return out.numpy()
