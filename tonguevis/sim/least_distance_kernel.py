"""warp-lang kernel for many least distance problems at once: :func:`tonguevis.sim.least_distance.least_distance_from`
compiled, one thread a problem.

The humps' projection below the palate (:mod:`tonguevis.sim.patch_contact`) solves some 3,000 such problems on a
/ka/ recording (84 unknowns, a few hundred rows, 10-30 active); the NumPy version spends its time on the call
overhead of its small arrays (a few dozen microseconds a step), here a step costs what its arithmetic does.  The
algorithm is the NumPy one step by step (Goldfarb-Idnani, the Gram inverse bordered and shrunk by its Schur
complement), with one refinement of the final active rows' equalities instead of NumPy's polish (a solve
afresh): the same optimum to rounding (tests/sim/test_least_distance.py).
"""

from __future__ import annotations

import os
import threading
from typing import Any

import numpy as np

from tonguevis.sim.contact_kernel import PARALLEL_WORKERS, thread_pool
from tonguevis.sim.least_distance import FEASIBLE, INDEPENDENT, MAX_STEPS, NEGATIVE

_lock = threading.Lock()
_kernel = None
_wp = None
_launched: set = set()  # the widths launched once (their kernels built)
BIG = 1e300  # no step (infinity)
CANDIDATES = 32  # violated rows a scan keeps, to join before the next scan
PARALLEL_PROBLEMS = 32  # a launch of at least twice this many problems is split over threads


def _build():  # noqa: C901 - one kernel, kept whole
    global _kernel, _wp
    with _lock:
        if _kernel is not None:
            return
        from tonguevis._backend import load_warp

        wp = load_warp()
        f64 = wp.float64

        @wp.kernel
        def dual_active_set(g: wp.array(dtype=Any), h: wp.array(dtype=f64), seg_start: wp.array2d(dtype=int),
                            seg_end: wp.array2d(dtype=int), n_seg: wp.array(dtype=int), slot: wp.array(dtype=int),
                            tol: wp.array(dtype=f64),
                            max_steps: int, independent: f64, negative: f64, big: f64,
                            active: wp.array2d(dtype=int), v: wp.array2d(dtype=f64), count: wp.array(dtype=int),
                            inverse: wp.array3d(dtype=f64), z: wp.array(dtype=Any), u: wp.array2d(dtype=f64),
                            r: wp.array2d(dtype=f64), cand: wp.array2d(dtype=int), status: wp.array(dtype=int)):
            b = wp.tid()
            f = slot[b]  # the problem's state (active rows, multipliers, Gram inverse, z) is kept by slot
            cap = active.shape[1]
            last_seg = n_seg[f] - 1
            s = count[f]
            zl = g[seg_start[f, 0]] * f64(0.0)  # rows and z are vectors of the problem's width
            for i in range(s):
                zl = zl + v[f, i] * g[active[f, i]]
            gp = zl
            p = int(-1)
            slack = f64(0.0)
            vp = f64(0.0)
            norm2 = f64(0.0)
            result = int(0)
            steps = int(0)
            running = int(1)
            n_cand = int(0)
            cand_cap = cand.shape[1]
            while running == 1:
                if p < 0:  # a violated row joins: the most violated of those the last scan found, else scan
                    low = big
                    at = int(-1)
                    for i in range(n_cand):
                        row = cand[f, i]
                        acc = wp.dot(g[row], zl) - h[row]
                        if acc < low:
                            low = acc
                            at = row
                    if low >= -tol[b]:  # none left: the newest rows, then (refined) all of them
                        at = int(-1)
                        for stage in range(2):
                            if at < 0 and running == 1:
                                first = last_seg
                                if stage == 1:
                                    first = int(0)
                                    # the active rows' equalities refined once (to rounding), then every row
                                    # checked: the end unless a row is violated after all
                                    for i in range(s):
                                        row = active[f, i]
                                        u[f, i] = h[row] - wp.dot(g[row], zl)
                                    for i in range(s):
                                        acc = f64(0.0)
                                        for j in range(s):
                                            acc = acc + inverse[f, i, j] * u[f, j]
                                        v[f, i] = v[f, i] + acc
                                        zl = zl + acc * g[active[f, i]]
                                low = big
                                n_cand = int(0)
                                for k in range(first, last_seg + 1):
                                    for row in range(seg_start[f, k], seg_end[f, k]):
                                        acc = wp.dot(g[row], zl) - h[row]
                                        if acc < -tol[b] and n_cand < cand_cap:
                                            cand[f, n_cand] = row
                                            n_cand = n_cand + 1
                                        if acc < low:
                                            low = acc
                                            at = row
                                if low >= -tol[b]:
                                    at = int(-1)
                                    if stage == 1:
                                        result = 1
                                        running = 0
                    if at >= 0:
                        p = at
                        gp = g[p]
                        slack = low
                        vp = f64(0.0)
                        norm2 = wp.dot(gp, gp)
                if running == 1 and steps >= max_steps:
                    running = 0
                if running == 1:
                    steps = steps + 1
                    for i in range(s):  # u = G_A g_p, r = (G_A G_Aᵀ)⁻¹ u, d = g_p - G_Aᵀ r
                        u[f, i] = wp.dot(g[active[f, i]], gp)
                    dl = gp
                    for i in range(s):
                        acc = f64(0.0)
                        for j in range(s):
                            acc = acc + inverse[f, i, j] * u[f, j]
                        r[f, i] = acc
                        dl = dl - acc * g[active[f, i]]
                    dd = wp.dot(dl, dl)
                    full = big
                    if dd > independent * norm2:
                        full = -slack / dd
                    release = big
                    leave = int(-1)
                    for i in range(s):
                        if r[f, i] > f64(0.0):
                            ratio = v[f, i] / r[f, i]
                            if ratio < release:
                                release = ratio
                                leave = i
                    if full >= big and release >= big:
                        running = 0  # dependent on the active rows, none to release: the NNLS decides
                    elif full <= release:
                        if s + 1 >= cap:
                            running = 0
                        else:  # p holds: it joins, the inverse bordered (Schur complement dd)
                            zl = zl + full * dl
                            for i in range(s):
                                v[f, i] = v[f, i] - full * r[f, i]
                                for j in range(s):
                                    inverse[f, i, j] = inverse[f, i, j] + r[f, i] * r[f, j] / dd
                                inverse[f, i, s] = -r[f, i] / dd
                                inverse[f, s, i] = -r[f, i] / dd
                            inverse[f, s, s] = f64(1.0) / dd
                            active[f, s] = p
                            v[f, s] = vp + full
                            s = s + 1
                            p = int(-1)
                    else:  # the row ``leave`` reaches zero first: it leaves (swapped last), p keeps going
                        zl = zl + release * dl
                        for i in range(s):
                            v[f, i] = v[f, i] - release * r[f, i]
                        vp = vp + release
                        slack = slack + release * dd
                        last = s - 1
                        keep_row = active[f, leave]
                        active[f, leave] = active[f, last]
                        active[f, last] = keep_row
                        keep_v = v[f, leave]
                        v[f, leave] = v[f, last]
                        v[f, last] = keep_v
                        for j in range(s):
                            tmp = inverse[f, leave, j]
                            inverse[f, leave, j] = inverse[f, last, j]
                            inverse[f, last, j] = tmp
                        for i in range(s):
                            tmp2 = inverse[f, i, leave]
                            inverse[f, i, leave] = inverse[f, i, last]
                            inverse[f, i, last] = tmp2
                        pivot = inverse[f, last, last]
                        for i in range(last):
                            for j in range(last):
                                inverse[f, i, j] = inverse[f, i, j] - inverse[f, i, last] * inverse[f, last, j] / pivot
                        s = last
            if result == 1:  # no multiplier below zero beyond rounding (a degenerate row)
                top = f64(0.0)
                for i in range(s):
                    top = wp.max(top, v[f, i])
                for i in range(s):
                    if v[f, i] < -negative * top:
                        result = 0
            z[f] = zl
            count[f] = s
            status[b] = result

        _kernel = dual_active_set
        _wp = wp


class LeastDistanceBatch:
    """``n`` least distance problems of ``width`` unknowns (a slot each) that grow by blocks of rows, and the state
    of each one's last answer (active rows, multipliers, Gram inverse), so the next call starts from it
    (:func:`~tonguevis.sim.least_distance.least_distance_from`'s start: its rows are all still there).

    The rows live in one store, appended block by block and never moved: a slot's rows are its segments of the
    blocks (up to ``blocks``), its active rows numbered in the store."""

    def __init__(self, n: int, width: int, blocks: int):
        _build()
        self.width, self.cap = width, width + 1
        self.active = np.zeros((n, self.cap), dtype=np.int32)
        self.weights = np.zeros((n, self.cap))
        self.count = np.zeros(n, dtype=np.int32)
        self.inverse = np.zeros((n, self.cap, self.cap))
        self.z = np.zeros((n, width))
        self.seg_start = np.zeros((n, blocks), dtype=np.int32)
        self.seg_end = np.zeros((n, blocks), dtype=np.int32)
        self.n_seg = np.zeros(n, dtype=np.int32)
        self.scale = np.zeros(n)  # max |h| of each slot's rows
        self._g, self._h, self.rows = np.empty((0, width)), np.empty(0), 0
        self._scratch = [np.zeros((n, self.cap)), np.zeros((n, self.cap))]
        self._cand = np.zeros((n, CANDIDATES), dtype=np.int32)  # the violated rows a scan found
        self._vector = _wp.types.vector(length=width, dtype=_wp.float64)

    def add(self, slots: np.ndarray, g: np.ndarray, h: np.ndarray, first_row: np.ndarray) -> None:
        """Rows for ``slots`` (b,): g (R, width), h (R,), slot j's rows first_row[j]:first_row[j + 1]."""
        n_rows = len(h)
        if self.rows + n_rows > len(self._h):  # grow the store (amortised: doubled)
            size = max(2 * (self.rows + n_rows), 1024)
            grown_g, grown_h = np.empty((size, self.width)), np.empty(size)
            grown_g[:self.rows], grown_h[:self.rows] = self._g[:self.rows], self._h[:self.rows]
            self._g, self._h = grown_g, grown_h
        self._g[self.rows:self.rows + n_rows], self._h[self.rows:self.rows + n_rows] = g, h
        at = self.n_seg[slots]
        self.seg_start[slots, at] = self.rows + first_row[:-1]
        self.seg_end[slots, at] = self.rows + first_row[1:]
        self.n_seg[slots] += 1
        if n_rows:
            lengths = np.diff(first_row)
            tops = np.zeros(len(slots))
            has = lengths > 0
            tops[has] = np.maximum.reduceat(np.abs(h), first_row[:-1][has])
            self.scale[slots] = np.maximum(self.scale[slots], tops)
        self.rows += n_rows

    def problem(self, slot: int) -> tuple[np.ndarray, np.ndarray]:
        """(g, h): the slot's rows, in the order they were added."""
        rows = np.concatenate([np.arange(a, b) for a, b in zip(self.seg_start[slot, :self.n_seg[slot]],
                                                              self.seg_end[slot, :self.n_seg[slot]])])
        return self._g[rows], self._h[rows]

    def forget(self, slots: np.ndarray) -> None:
        """The next call starts these slots from z = 0 (no active rows)."""
        self.count[slots] = 0

    def solve(self, slots: np.ndarray, max_steps: int = MAX_STEPS) -> np.ndarray:
        """(len(slots),) bool: which problems were solved; their z in ``self.z[slots]``.  One not solved
        (False: no progress within ``max_steps``, or rows nearly dependent on the active ones and none to
        release) is left to the NNLS and forgotten."""
        wp = _wp
        slots = np.asarray(slots, dtype=np.int32)
        status = np.zeros(len(slots), dtype=np.int32)
        if len(slots) == 0:
            return status.astype(bool)
        tol = FEASIBLE * np.maximum(self.scale[slots], 1e-300)

        def arr(a, dtype):
            return wp.array(a, dtype=dtype, device="cpu", copy=False)

        f64, i32 = wp.float64, wp.int32
        shared = [arr(self._g[:max(self.rows, 1)], self._vector), arr(self._h[:max(self.rows, 1)], f64),
                  arr(self.seg_start, i32), arr(self.seg_end, i32), arr(self.n_seg, i32)]
        state = [arr(self.active, i32), arr(self.weights, f64), arr(self.count, i32), arr(self.inverse, f64),
                 arr(self.z, self._vector), *(arr(a, f64) for a in self._scratch), arr(self._cand, i32)]

        def launch(part: slice) -> None:  # each problem writes only its slot's state: parts run side by side
            wp.launch(_kernel, dim=len(slots[part]), device="cpu",
                      inputs=[*shared, arr(slots[part], i32), arr(tol[part], f64), int(max_steps),
                              f64(INDEPENDENT), f64(NEGATIVE), f64(BIG)],
                      outputs=[*state, arr(status[part], i32)])
            wp.synchronize_device("cpu")

        workers = min(PARALLEL_WORKERS, os.cpu_count() or 1, len(slots) // PARALLEL_PROBLEMS)
        if workers <= 1 or self.width not in _launched:
            # a width's first launch builds its kernel: never from two threads at once (warp's build is lazy
            # and not thread-safe: a second thread found the kernel half built)
            launch(slice(None))
            _launched.add(self.width)
        else:  # a launch runs on one core and releases the GIL
            edges = np.linspace(0, len(slots), workers + 1).astype(int)
            list(thread_pool().map(launch, [slice(a, b) for a, b in zip(edges[:-1], edges[1:])]))
        solved = status.astype(bool)
        self.forget(slots[~solved])
        return solved
