#!/usr/bin/env python
"""Latency of the live view: a recording streamed through the replay server into the live window.

Run under a display (Xvfb and software OpenGL are the target):

    xvfb-run -a python scripts/bench_live.py --json /tmp/live.json [--seconds 20] [--file F]

The replay server (:class:`tonguevis.live.server.ReplayServer`) streams the recording (the demo
by default) at its own rate, looped, over TCP on this machine to a WaveFront client
(:class:`tonguevis.live.source.WaveFrontSource`) feeding :class:`tonguevis.gui.live_window.LiveWindow`
(default size 1280 x 800, its 3D view about 930 x 780).  After the rest is taken and a second
of warm-up, for ``--seconds`` s it records, for every drawn frame:

* ``latency_ms``: from the frame's arrival at the socket (``LiveFrame.arrival_s``, read by the
  client's thread) to the end of the paint of the 3D view that shows it (VTK's render returned,
  the image read back and painted): median, p95, max;
* ``dropped_frames``: frames received but not drawn (a newer one came before they could be),
  and ``skipped_frames`` (not even simulated: a burst after a stall);
* ``fps``: frames drawn per second; ``stream_hz``: frames received per second;
* ``stages_ms``: medians and p95 of the per-frame stages: ``simulate`` (head correction, drive,
  one Newmark step, for every frame received in the tick), ``reconstruct`` (the surface nodes of
  the drawn frame), ``scene`` (the actors' points, normals, targets, midsagittal section),
  ``render`` (VTK's render and the paint: ``submit``, VTK's render call, and ``paint``, the read-back of
  the rasterised frame and its paint), ``tick`` (the whole poll);
* ``backlog``: frames taken from the source per tick (median and max: every frame that came since
  the last tick, so a backlog would show as a growing count), the latency's median over the first and
  the last third of the run (which also moves with the machine's load) and the source's queue left at
  the end; ``machine.load_average_1min_at_end`` says how busy the machine was.

The figures are this machine's; CPU count and OpenGL renderer are in the JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numpy as np


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", required=True, help="write the figures here")
    parser.add_argument("--seconds", type=float, default=20.0, help="seconds measured (default 20)")
    parser.add_argument("--file", help="a recording to stream (default: the demo)")
    parser.add_argument("--sensors", help="its sensor map (default: beside the file)")
    parser.add_argument("--modes", type=int, default=100, help="modes of the live model (default 100, the replay's)")
    parser.add_argument("--size", default="1280x800", help="window size (default 1280x800)")
    parser.add_argument("--targets", type=int, default=3, help="targets shown (default 3: static, oscillating, "
                                                                "following)")
    parser.add_argument("--render-scale", type=float, default=None,
                        help="the 3D view's render scale (default: the live window's, LIVE_RENDER_SCALE)")
    args = parser.parse_args()

    os.environ.setdefault("QT_QPA_PLATFORM", "xcb")
    from PySide6.QtCore import QEventLoop, QTimer

    from tonguevis.gui.app import application
    from tonguevis.gui.live_window import LiveWindow
    from tonguevis.live.server import ReplayServer
    from tonguevis.live.session import LiveSession
    from tonguevis.live.source import WaveFrontSource
    from tonguevis.paths import DEMO_RECORDING
    from tonguevis.workflows import open_recording

    _app = application()  # kept: the QApplication lives while the window does

    def wait(ms: int) -> None:
        # An event loop, not processEvents() in a Python loop (see LiveViews._paint, tonguevis.gui.live_views).
        loop = QEventLoop()
        QTimer.singleShot(int(ms), loop.quit)
        loop.exec()

    rec = open_recording(args.file or DEMO_RECORDING, args.sensors, audio=False, labels=False)
    import tempfile

    from tonguevis.sim.settings import RunSettings

    profiles = tempfile.mkdtemp(prefix="bench_live_")
    width, height = (int(v) for v in args.size.lower().split("x"))
    with ReplayServer(rec, loop=True) as server:
        window = LiveWindow(WaveFrontSource("127.0.0.1", server.port),
                            LiveSession(RunSettings(modes=args.modes), profiles_root=profiles))
        window.quiet = True
        if args.render_scale is not None and hasattr(window.plotter, "set_render_scale"):
            window.plotter.set_render_scale(args.render_scale)
        window.resize(width, height)
        window.show()
        deadline = time.perf_counter() + 60
        while window.simulator is None and time.perf_counter() < deadline:
            wait(100)
        if window.simulator is None:
            raise SystemExit(f"no rest taken within 60 s: {window.rest_label.text()}")
        for add in (window.add_static_target, window.add_oscillating_target, window.add_following_target)[:args.targets]:
            add()
        wait(1000)  # warm-up: the first frames with the tongue build its actors
        window._reset_counters()
        status0 = window.source.status()
        start = time.perf_counter()
        wait(1000 * args.seconds)
        elapsed = time.perf_counter() - start
        figures = window.figures()
        status = window.source.status()
        queue_left = window.source._queue.qsize() if window.source._queue is not None else 0
        latencies = np.array(window.latencies_ms)
        stages = list(window.stage_ms)
        gl = window.plotter.ren_win.ReportCapabilities().splitlines()
        renderer = next((line.split(":", 1)[1].strip() for line in gl if "OpenGL renderer" in line), "unknown")
        view = window.plotter.interactor.size()
        window.close()

    third = max(1, len(latencies) // 3)
    out = {
        "file": str(args.file or DEMO_RECORDING), "rate_hz": rec.rate, "seconds": elapsed, "modes": args.modes,
        "window": [width, height], "view_3d": [view.width(), view.height()],
        "latency_ms": {"median": float(np.median(latencies)), "p95": float(np.percentile(latencies, 95)),
                       "max": float(latencies.max())},
        "dropped_frames": figures["dropped_frames"], "skipped_frames": figures["skipped_frames"],
        "frames_drawn": figures["frames_drawn"], "frames_received": figures["frames_received"],
        "fps": figures["fps"], "stream_hz": (status.frames - status0.frames) / elapsed,
        "render_scale": float(getattr(window.plotter, "render_scale", 1.0)), "load_average": os.getloadavg()[0],
        "stages_ms": {key: {"median": float(np.median([s.get(key, 0.0) for s in stages])),
                            "p95": float(np.percentile([s.get(key, 0.0) for s in stages], 95))}
                      for key in ("simulate", "reconstruct", "scene", "render", "submit", "paint", "tick")},
        "backlog": {"frames_per_tick_median": float(np.median([s.get("pending", 1) for s in stages])),
                    "frames_per_tick_max": int(max(s.get("pending", 1) for s in stages)),
                    "latency_median_first_third_ms": float(np.median(latencies[:third])),
                    "latency_median_last_third_ms": float(np.median(latencies[-third:])),
                    "queue_left": int(queue_left), "source_dropped": status.dropped - status0.dropped},
        "reconnects": status.reconnects - status0.reconnects,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "opengl_renderer": renderer,
                    "load_average_1min_at_end": os.getloadavg()[0]},
    }
    with open(args.json, "w", encoding="utf-8") as f:
        json.dump(out, f, indent=1)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
