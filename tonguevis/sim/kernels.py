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
_figures_kernel = None
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

        @wp.kernel
        def surface_figures(lin: wp.array2d(dtype=wp.vec3f), w: wp.array2d(dtype=wp.vec3f),
                            rest: wp.array(dtype=wp.vec3d), faces: wp.array2d(dtype=int), warping: int,
                            moved: wp.array2d(dtype=wp.vec3d),
                            volume: wp.array(dtype=wp.float64), largest: wp.array(dtype=wp.float64)):
            # One frame per thread: warp each surface node's displacement (in float64 from the float32
            # products), keep the largest, then the enclosed volume of the moved surface (moved: scratch).
            f = wp.tid()
            top = wp.float64(0.0)
            for i in range(lin.shape[1]):
                d = wp.vec3d(lin[f, i])
                if warping != 0:
                    wi = wp.vec3d(w[f, i])
                    a, b = coefficients(wp.length(wi))
                    wd = wp.cross(wi, d)
                    d = d + a * wd + b * wp.cross(wi, wd)
                moved[f, i] = rest[i] + d
                top = wp.max(top, wp.dot(d, d))
            acc = wp.float64(0.0)
            for k in range(faces.shape[0]):
                acc = acc + wp.dot(moved[f, faces[k, 0]], wp.cross(moved[f, faces[k, 1]], moved[f, faces[k, 2]]))
            volume[f] = acc / wp.float64(6.0)
            largest[f] = wp.sqrt(top)

        global _flux_kernel, _figures_kernel
        _flux_kernel = surface_flux
        _figures_kernel = surface_figures
        _wp = wp
        _kernel = {np.dtype(np.float64): (warp_rotate, wp.vec3d), np.dtype(np.float32): (warp_rotate32, wp.vec3f)}


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


def surface_figures(lin: np.ndarray, w: np.ndarray | None, rest: np.ndarray, faces: np.ndarray,
                    warping: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(volume (F,) m³, largest displacement (F,) m) of the surface nodes, one frame per CPU thread.

    lin : (F, k, 3) the nodes' linear displacement Φq, m; w : (F, k, 3) their rotation vectors Wq
    (unused without ``warping``); both float32 (the products are the costly part; the rest runs in
    float64); rest : (k, 3) their rest positions, m; faces : (f, 3) the closed outward surface in
    these k nodes.  The warped displacement is R̃(w) Φq as in :func:`rotate_accumulated_compiled`,
    the volume ⅙ Σ p0 · (p1 × p2) as in :func:`enclosed_volumes`; fused, nothing of a frame but its
    figures is written out (a test checks them against the float64 whole-array reference).
    """
    _build()
    wp = _wp
    n_frames, k = lin.shape[:2]
    volume, largest = np.empty(n_frames), np.empty(n_frames)
    if n_frames == 0:
        return volume, largest
    lin = np.ascontiguousarray(lin, dtype=np.float32).reshape(n_frames, k, 3)
    w = lin if w is None else np.ascontiguousarray(w, dtype=np.float32).reshape(n_frames, k, 3)
    arrays = [wp.array(a, dtype=dtype, device="cpu", copy=False) for a, dtype in (
        (lin, wp.vec3f), (w, wp.vec3f), (np.ascontiguousarray(rest, dtype=np.float64), wp.vec3d))]
    faces_a = wp.array(np.ascontiguousarray(faces, dtype=np.int32), dtype=wp.int32, device="cpu")
    moved = wp.empty((n_frames, k), dtype=wp.vec3d, device="cpu")
    outs = [wp.array(a, dtype=wp.float64, device="cpu", copy=False) for a in (volume, largest)]
    wp.launch(_figures_kernel, dim=n_frames, inputs=[*arrays, faces_a, int(bool(warping)), moved], outputs=outs,
              device="cpu")
    wp.synchronize_device("cpu")
    return volume, largest
