"""The frame loop and the per-frame figures side by side (what :func:`~tonguevis.sim.simulate` runs).

The compiled frame loop (:class:`~tonguevis.sim.newmark_kernel.CompiledIntegrator`) is
sequential and runs on one core.  Integrated first and measured after, a 30-minute
recording spent 14 s in the loop and then 10 s reconstructing every frame's surface
for the per-frame figures (:func:`~tonguevis.sim.figures.frame_figures`).  Here the loop
runs segment by segment in a thread of its own (a warp launch releases the GIL) while
the calling thread measures the segments already integrated, with one BLAS thread so
the two stay on their own cores (also for the segments measured after the loop is done:
the figures do not depend on timing).
Segments resume from the integrator's state, so q is bit for bit that of one launch
and the figures those of :func:`frame_figures` on the whole q (a test checks both).

After each segment ``on_segment(done)`` may look at the first ``done`` frames, which are
final: the app shows the first seconds of a long recording from there.
"""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass
from typing import Callable

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.sim.figures import FrameFigures, frame_figures
from tonguevis.sim.newmark import IntegrationResult, NewmarkSettings

#: Frames integrated per launch: 0.1 s of the frame loop, short enough to measure while the next runs.
SEGMENT_FRAMES = 2048


@dataclass
class Progressive:
    """The arrays :func:`integrate_and_measure` fills, frame ``0`` to ``done`` final at any time.

    result : the :class:`IntegrationResult` (F frames; q̇, q̈ not kept); figures : the
    :class:`FrameFigures` (volume change, largest surface displacement); done : frames final.
    """

    result: IntegrationResult
    figures: FrameFigures
    done: int = 0


def integrate_and_measure(model, eigenvalues: np.ndarray, phi_s: np.ndarray, w_s: np.ndarray, targets: np.ndarray,
                          settings: NewmarkSettings, compliance: np.ndarray, warping: bool = True,
                          progress: ProgressCallback | None = None, segment: int | None = None,
                          on_segment: Callable[[Progressive], None] | None = None,
                          extend: Callable[[np.ndarray, int, int], np.ndarray] | None = None) -> Progressive:
    """Integrate ``targets`` (F, S, 3) m with ``compliance`` (F, S) m/N on the compiled backend and
    measure every frame, overlapped (see the module docstring); returns the filled :class:`Progressive`.

    segment : frames per launch (default :data:`SEGMENT_FRAMES`).
    on_segment(progressive) : called on this thread after each segment is measured
    (``progressive.done`` frames final).  ``progress(done, total, message)`` is called
    likewise and may raise (e.g. Cancelled): the loop's thread then stops after its segment.
    extend(q, start, end) : more coordinates of frames start..end-1 from the loop's q (c, m), e.g.
    the sensor patches' (:mod:`tonguevis.sim.patches`), appended to ``result.q`` on this thread before
    the segment is measured (``model`` then has the extended basis).
    """
    from tonguevis._blas import single_threaded_blas
    from tonguevis.sim.newmark_kernel import CompiledIntegrator

    segment = SEGMENT_FRAMES if segment is None else max(1, int(segment))
    n_frames, n_sensors = targets.shape[:2]
    m = len(eigenvalues)
    integrator = CompiledIntegrator(eigenvalues, phi_s, w_s, settings, n_sensors=n_sensors, rates=False)
    extra = 0 if extend is None else int(np.asarray(extend(np.zeros((1, m)), 0, 1)).shape[1])
    compliance = np.broadcast_to(np.asarray(compliance, dtype=np.float64), (n_frames, n_sensors))
    out = Progressive(
        IntegrationResult(np.empty((n_frames, m + extra)), None, None, np.empty((n_frames, n_sensors)),
                          np.zeros(n_frames, dtype=bool), np.zeros(n_frames, dtype=np.int64),
                          np.zeros(n_frames, dtype=bool)),
        FrameFigures(np.empty(n_frames), np.empty(n_frames)))
    ready: queue.Queue = queue.Queue()
    stop = threading.Event()

    def loop() -> None:
        try:
            for start in range(0, n_frames, segment):
                if stop.is_set():
                    break
                end = min(start + segment, n_frames)
                part = integrator.advance(targets[None, start:end], compliance[None, start:end])[0]
                r = out.result
                r.q[start:end, :m], r.residual[start:end] = part.q, part.residual
                r.converged[start:end] = part.converged
                r.iterations[start:end], r.recovered[start:end] = part.iterations, part.recovered
                ready.put((start, end))
        except BaseException as exc:  # handed to the measuring thread, which raises it
            ready.put(exc)
        finally:
            ready.put(None)

    thread = threading.Thread(target=loop, name="tonguevis-frame-loop", daemon=True)
    thread.start()
    try:
        while True:
            item = ready.get()
            if item is None:
                break
            if isinstance(item, BaseException):
                raise item
            start, end = item
            # One core measures while the other integrates; always so, also once the loop is
            # done: float32 products split over other thread counts round differently, and the
            # figures must not depend on how far the loop had got (batch and CLI agree bit for bit).
            with single_threaded_blas():
                if extend is not None:
                    out.result.q[start:end, m:] = extend(out.result.q[start:end, :m], start, end)
                part = frame_figures(model, out.result.q[start:end], warping, "warp", workers=1)
            out.figures.volume_change[start:end] = part.volume_change
            out.figures.largest_displacement[start:end] = part.largest_displacement
            out.done = end
            report(progress, end, n_frames, "integrating and measuring, frame by frame")
            if on_segment is not None:
                on_segment(out)
    finally:
        stop.set()
        thread.join()
    return out
