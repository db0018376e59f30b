"""warp-lang kernel for the contact's clearance queries: many points against one palate height field.

The contact (:mod:`tonguevis.sim.contact`) asks, for every frame, how far
each candidate surface node lies below the palate: F × k queries (1,762 ×
310 on the demo), each a change of frame, a gather of four grid heights and
a bilinear interpolation.  In NumPy that is a dozen whole-array passes
(0.1-0.2 s a simulation, several times over); here it is one pass, one
thread per (frame, node), the positions formed inside the kernel from the
rest positions, the nodes' displacements and the frame's jaw offset, so the
(F, k, 3) query array is never built.

The arithmetic is :meth:`tonguevis.palate.PalateSurface.clearance`'s, step by
step but with reciprocals for its divisions (the NumPy reference; a test proves
them equal to 1e-12 m).
"""

from __future__ import annotations

import os
import threading

import numpy as np

#: Queries of at least this many points per thread are split over threads (at most PARALLEL_WORKERS).
PARALLEL_POINTS = 100_000
PARALLEL_WORKERS = 4

_lock = threading.Lock()
_kernel = None
_wp = None


def _build():
    global _kernel, _wp
    with _lock:
        if _kernel is not None:
            return
        from tonguevis._backend import load_warp

        wp = load_warp()
        f64 = wp.float64

        @wp.kernel
        def clearance(base: wp.array(dtype=wp.vec3d), disp: wp.array2d(dtype=wp.vec3d),
                      offset: wp.array(dtype=wp.vec3d), z: wp.array2d(dtype=f64), rot: wp.mat33d, scale: f64,
                      shift: wp.vec3d, x0: f64, x1: f64, y0: f64, y1: f64, want_normal: int,
                      lift: wp.array(dtype=f64), g: wp.array2d(dtype=f64), has_lift: int,
                      gap: wp.array2d(dtype=f64), normal: wp.array2d(dtype=wp.vec3d)):
            f, k = wp.tid()
            p = (base[k] + disp[f, k]) + offset[f] - shift
            # the palate's own frame: (p - t) R / s, as PalateSurface._to_own (reciprocals: a division
            # costs as much as the rest of the query; the result moves by a few ulps)
            inv_scale = f64(1.0) / scale
            ox = (p[0] * rot[0, 0] + p[1] * rot[1, 0] + p[2] * rot[2, 0]) * inv_scale
            oy = (p[0] * rot[0, 1] + p[1] * rot[1, 1] + p[2] * rot[2, 1]) * inv_scale
            oz = (p[0] * rot[0, 2] + p[1] * rot[1, 2] + p[2] * rot[2, 2]) * inv_scale
            nx = z.shape[1]
            ny = z.shape[0]
            inv_dx = f64(1.0) / (x1 - x0)
            inv_dy = f64(1.0) / (y1 - y0)
            fx = (ox - x0) * inv_dx
            fy = (oy - y0) * inv_dy
            inside = fx >= f64(0.0) and fx <= f64(nx - 1) and fy >= f64(0.0) and fy <= f64(ny - 1)
            # the cell, clipped to the grid as NumPy's (outside the footprint the height is NaN anyway)
            i = 0
            j = 0
            if fx == fx:  # not NaN
                i = int(wp.clamp(wp.floor(fx), f64(0.0), f64(nx - 2)))
            if fy == fy:
                j = int(wp.clamp(wp.floor(fy), f64(0.0), f64(ny - 2)))
            tx = wp.clamp(fx - f64(i), f64(0.0), f64(1.0))
            ty = wp.clamp(fy - f64(j), f64(0.0), f64(1.0))
            z00 = z[j, i]
            z10 = z[j, i + 1]
            z01 = z[j + 1, i]
            z11 = z[j + 1, i + 1]
            h = (f64(1.0) - ty) * ((f64(1.0) - tx) * z00 + tx * z10) + ty * ((f64(1.0) - tx) * z01 + tx * z11)
            dx = ((f64(1.0) - ty) * (z10 - z00) + ty * (z11 - z01)) * inv_dx
            dy = ((f64(1.0) - tx) * (z01 - z00) + tx * (z11 - z10)) * inv_dy
            if has_lift != 0:  # the velum lifted by lift[f] times its share g, in the palate's own units
                a = lift[f] * inv_scale
                g00 = g[j, i]
                g10 = g[j, i + 1]
                g01 = g[j + 1, i]
                g11 = g[j + 1, i + 1]
                h = h + a * ((f64(1.0) - ty) * ((f64(1.0) - tx) * g00 + tx * g10)
                             + ty * ((f64(1.0) - tx) * g01 + tx * g11))
                dx = dx + a * ((f64(1.0) - ty) * (g10 - g00) + ty * (g11 - g01)) * inv_dx
                dy = dy + a * ((f64(1.0) - tx) * (g01 - g00) + tx * (g11 - g10)) * inv_dy
            if not inside:
                h = f64(wp.nan)
            inv_norm = f64(1.0) / wp.sqrt(dx * dx + dy * dy + f64(1.0))
            gap[f, k] = (h - oz) * inv_norm * scale
            if want_normal != 0:
                n = wp.vec3d(dx * inv_norm, dy * inv_norm, -inv_norm)
                normal[f, k] = wp.vec3d(n[0] * rot[0, 0] + n[1] * rot[0, 1] + n[2] * rot[0, 2],
                                        n[0] * rot[1, 0] + n[1] * rot[1, 1] + n[2] * rot[1, 2],
                                        n[0] * rot[2, 0] + n[1] * rot[2, 1] + n[2] * rot[2, 2])

        _kernel = clearance
        _wp = wp


class Clearance:
    """Clearance queries of a fixed set of points (rest positions ``base`` (k, 3), m) below ``palate``
    (a PalateSurface), displaced per call: the palate's grid and the rest positions are handed to
    warp once, so a query of one frame's 310 nodes (the active-set solve's, several per frame) costs
    little more than the launch."""

    def __init__(self, palate, base: np.ndarray):
        _build()
        wp = _wp
        self.k = len(base)
        self._base_np = np.ascontiguousarray(base, dtype=np.float64).reshape(-1, 3)
        self.base = self._base_np  # (k, 3) m, the points' rest positions
        self._z_np = np.ascontiguousarray(palate.z, dtype=np.float64)
        x, y = np.asarray(palate.x, dtype=np.float64), np.asarray(palate.y, dtype=np.float64)
        self._base = wp.array(self._base_np, dtype=wp.vec3d, device="cpu", copy=False)
        self._z = wp.array(self._z_np, dtype=wp.float64, device="cpu", copy=False)
        self._params = [wp.mat33d(*np.asarray(palate.rotation, dtype=np.float64).ravel()), float(palate.scale),
                        wp.vec3d(*np.asarray(palate.translation, dtype=np.float64)),
                        float(x[0]), float(x[1]), float(y[0]), float(y[1])]
        self._no_normal = wp.empty((1, 1), dtype=wp.vec3d, device="cpu")
        shape = getattr(palate, "lift_shape", None)
        self._g_np = np.ascontiguousarray(shape if shape is not None else np.zeros((1, 1)), dtype=np.float64)
        self._g = wp.array(self._g_np, dtype=wp.float64, device="cpu", copy=False)
        self._liftable = shape is not None

    def __call__(self, disp: np.ndarray, offset: np.ndarray,
                 normals: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """(gap (F, k) m, normals (F, k, 3) or None) of base[k] + disp[f, k] + offset[f];
        disp : (F, k, 3) m, offset : (F, 3) m, or (F, 4) with the velum's lift; see :func:`clearances`."""
        wp = _wp
        offset = np.asarray(offset, dtype=np.float64)
        offset = offset.reshape(-1, offset.shape[-1] if offset.ndim > 1 else len(offset))
        lift = np.ascontiguousarray(offset[:, 3]) if offset.shape[1] > 3 else np.zeros(len(offset))
        has_lift = int(self._liftable and bool(np.any(lift)))
        offset = np.ascontiguousarray(offset[:, :3])
        n_frames = len(offset)
        disp = np.ascontiguousarray(disp, dtype=np.float64).reshape(n_frames, self.k, 3)
        gap = np.empty((n_frames, self.k))
        if n_frames == 0 or self.k == 0:
            return gap, (np.empty((n_frames, self.k, 3)) if normals else None)
        normal = np.empty((n_frames, self.k, 3)) if normals else None

        def launch(rows: slice) -> None:
            outs = [wp.array(gap[rows], dtype=wp.float64, device="cpu", copy=False),
                    wp.array(normal[rows], dtype=wp.vec3d, device="cpu", copy=False) if normals else self._no_normal]
            wp.launch(_kernel, dim=(len(gap[rows]), self.k), device="cpu",
                      inputs=[self._base, wp.array(disp[rows], dtype=wp.vec3d, device="cpu", copy=False),
                              wp.array(offset[rows], dtype=wp.vec3d, device="cpu", copy=False), self._z,
                              *self._params, int(normals),
                              wp.array(lift[rows], dtype=wp.float64, device="cpu", copy=False), self._g, has_lift],
                      outputs=outs)
            wp.synchronize_device("cpu")

        workers = min(PARALLEL_WORKERS, os.cpu_count() or 1, n_frames * self.k // PARALLEL_POINTS)
        if workers <= 1:
            launch(slice(None))
        else:  # a launch runs on one core and releases the GIL: the frames in a few blocks, side by side
            edges = np.linspace(0, n_frames, workers + 1).astype(int)
            list(thread_pool().map(launch, [slice(a, b) for a, b in zip(edges[:-1], edges[1:])]))
        return gap, normal


_executor = None


def thread_pool():
    """The threads the large queries are split over, started once: a new pool a query cost its thread
    starts, up to 5 ms each on two busy cores (a simulation with a palate makes a dozen such queries);
    also :class:`~tonguevis.sim.least_distance_kernel.LeastDistanceBatch`'s launches."""
    global _executor
    with _lock:
        if _executor is None:
            from concurrent.futures import ThreadPoolExecutor

            _executor = ThreadPoolExecutor(PARALLEL_WORKERS, thread_name_prefix="tonguevis-clearance")
        return _executor


def clearances(palate, base: np.ndarray, disp: np.ndarray, offset: np.ndarray,
               normals: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Clearance below ``palate`` (a PalateSurface) of the points base[k] + disp[f, k] + offset[f].

    base : (k, 3) rest positions, m; disp : (F, k, 3) displacements, m; offset : (F, 3), m
    (the jaw's offset carrying the tongue into the palate's frame), or (F, 4) with the velum's lift
    (:func:`tonguevis.sim.contact.palate_offsets`).  Returns (gap (F, k) m,
    NaN outside the palate's footprint, negative inside it; normals (F, k, 3) or None), as
    :meth:`~tonguevis.palate.PalateSurface.clearance` of the (F·k, 3) points.
    """
    return Clearance(palate, base)(disp, offset, normals)
