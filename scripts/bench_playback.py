#!/usr/bin/env python
"""Playback frame rate of the desktop app under Xvfb (or any display), and where each frame's time goes.

Opens the real window (with the Energy, Morph and Segmentation tabs, as
``tonguevis view`` does) on a demo recording, simulates it, lets the plots
settle, then plays for a few seconds and counts the frames drawn.  Per frame:

- ``render_ms``: the VTK render of the four views (the render window's
  Render, wall time), and ``views_ms`` the share of each view (its renderer's
  Render); ``render_cpu_ms`` the CPU the process spent in it (every thread:
  Mesa's llvmpipe renders with several);
  since the image views render off screen with no buffer swap, this is the
  frame's submission: Mesa's threads rasterise it afterwards, while the GUI
  thread goes on, and ``readback_ms`` is the wait for what is left of that
  plus the copy of the pixels at the paint;
- ``update_ms``: writing the frame's points, scalars and normals in place;
- ``other_ms``: the rest of the frame (Qt events, the plots' cursors, the
  status line, the transport bar); ``plot_draws``: full matplotlib redraws
  during playback (there should be none);
- ``cpu_ms``: the process's CPU time per frame, the figure that does not
  depend on how loaded the machine is (``fps_cpu_bound`` = 1000 / cpu_ms when
  the frame's work fits one core's worth of waiting);
- ``lag_ms``: how far the frame shown trails the playback clock when it is
  painted (mean, max; negative: ahead): playback drops frames instead of
  delaying them, so this stays within about a frame and does not grow.

The machine's load average is written with every figure: on a shared,
loaded machine the wall-clock figures (fps, render_ms) are slower than on an
idle one, and the CPU figures and the shares are what to compare.

Run: xvfb-run -a -s "-screen 0 1600x1000x24" python scripts/bench_playback.py [--seconds 5] [--json OUT]
     [--no-context] [--screenshot PNG] [--profile]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def load_model(name: str):
    from tonguevis.sim import TongueModel

    if name == "default":
        return TongueModel.default(), "tonguevis default tongue", "speaker"
    if name == "artisynth":
        sys.path.insert(0, str(REPO / "scripts"))
        from bench_segmentation import load_model as artisynth

        model, label = artisynth()
        return model, label, "rule" if "fallback" in label else "speaker"
    from tests.gui.conftest import block_model

    return block_model(), "block test model", "rule"


def commit() -> str:
    try:
        out = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
        dirty = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True).stdout.strip()
        return out.stdout.strip() + ("+dirty" if dirty else "")
    except OSError:
        return "unknown"


def gl_renderer(render_window) -> str:
    try:
        info = render_window.ReportCapabilities()
    except Exception:  # noqa: BLE001 (diagnostic only)
        return "unknown"
    for line in info.splitlines():
        if "OpenGL renderer string" in line:
            return line.split(":", 1)[1].strip()
    return "unknown"


def x_server_pid() -> int | None:
    """The process of the X server on $DISPLAY (Xvfb), if it runs on this machine."""
    display = os.environ.get("DISPLAY", "")
    number = display.split(":")[-1].split(".")[0] if ":" in display else ""
    if not number:
        return None
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            words = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if words and Path(words[0].decode(errors="replace")).name.startswith(("Xvfb", "Xorg", "X")) \
                and f":{number}".encode() in words:
            return int(entry.name)
    return None


def cpu_seconds(pid: int | None) -> float:
    """User + system CPU seconds of process ``pid`` (0 when unknown)."""
    if pid is None:
        return 0.0
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


def thread_cpu_seconds() -> dict[str, float]:
    """CPU seconds (user + system) of each thread of this process, summed by thread name
    (the GUI thread is the process's name; Mesa's rasterisers are ``llvmpipe-N``)."""
    out: dict[str, float] = {}
    tick = os.sysconf("SC_CLK_TCK")
    for task in Path("/proc/self/task").iterdir():
        try:
            name = (task / "comm").read_text().strip()
            fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if task.name == str(os.getpid()):
            name = "GUI thread"
        elif name.startswith("llvmpipe"):
            name = "llvmpipe"
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return out


class Timings:
    """Wall and CPU time of the renders (per view too), the buffer updates and the plots' redraws."""

    def __init__(self, window, finish_views: bool = False):
        from tonguevis.render.scene import TongueScene

        self.window = window
        self.finish_views = finish_views
        self.reset()
        scene = window.view3d.scene
        original = TongueScene.update
        timings = self

        def timed_update(this, *a, **k):
            t = time.perf_counter()
            original(this, *a, **k)
            timings.update += time.perf_counter() - t
            timings.updates += 1

        scene.update = timed_update.__get__(scene)
        plotter = window.view3d.plotter
        read_image = getattr(plotter, "_read_image", None)  # the image views' read-back (not pyvistaqt's)
        if read_image is not None:
            def timed_read():
                t, c = time.perf_counter(), time.thread_time()
                read_image()
                timings.readback += time.perf_counter() - t
                timings.readback_cpu += time.thread_time() - c

            plotter._read_image = timed_read
        render_window = self.render_window = window.view3d.plotter.render_window
        render_window.AddObserver("StartEvent", self._render_start)
        render_window.AddObserver("EndEvent", self._render_end)
        self.view_names = ["main", "top", "front", "lateral"]
        for k, renderer in enumerate(window.view3d.plotter.renderers):
            renderer.AddObserver("StartEvent", lambda *_a, k=k: self._view_start(k))
            renderer.AddObserver("EndEvent", lambda *_a, k=k: self._view_end(k))
        for plot in self.plots():
            plot.mpl_connect("draw_event", self._plot_drawn)
        from PySide6.QtCore import QObject

        class PaintWatch(QObject):
            def eventFilter(watch, watched, event):  # noqa: N802, N805 (Qt name)
                return timings.eventFilter(watched, event)

        self._paint_watch = PaintWatch()
        window.view3d.plotter.interactor.installEventFilter(self._paint_watch)

    def plots(self):
        from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg

        return self.window.findChildren(FigureCanvasQTAgg)

    def reset(self) -> None:
        self.update = self.render = self.render_cpu = self.readback = self.readback_cpu = 0.0
        self.updates = self.renders = self.plot_draws = 0
        self.views = np.zeros(4)
        self.lags: list[float] = []
        self._t = self._c = 0.0
        self._v = np.zeros(4)

    def _render_start(self, *_):
        self._t, self._c = time.perf_counter(), time.process_time()

    def _render_end(self, *_):
        self.render += time.perf_counter() - self._t
        self.render_cpu += time.process_time() - self._c
        self.renders += 1

    def eventFilter(self, _watched, event) -> bool:  # noqa: N802 (Qt name)
        from PySide6.QtCore import QEvent

        # The picture's lag is taken when the 3D views are painted: the clock then, against the
        # time the painted frame was drawn for (drawn ahead during pipelined playback).
        if event.type() == QEvent.Type.Paint:
            playback, view3d = self.window.playback, self.window.view3d
            if self.window.state.playing and playback.clock is not None:
                self.lags.append(playback.clock.time() - getattr(view3d, "shown_time", view3d.cursor_time))
        return False

    def _view_start(self, k: int) -> None:
        if self.finish_views:
            self.render_window.WaitForCompletion()
        self._v[k] = time.perf_counter()

    def _view_end(self, k: int) -> None:
        # Mesa's llvmpipe rasterises when the commands are flushed (at the swap): without a
        # glFinish here a view's time is only the submission of its commands.
        if self.finish_views:
            self.render_window.WaitForCompletion()
        self.views[k] += time.perf_counter() - self._v[k]

    def _plot_drawn(self, _event) -> None:
        self.plot_draws += 1


def install_event_timer() -> dict:
    """Make the QApplication one whose notify() times every event (by type and receiver class)."""
    from PySide6.QtWidgets import QApplication

    times: dict = {}
    nested: list[float] = []  # time of the events nested in each event being handled
    nested_cpu: list[float] = []  # and the GUI thread's CPU time in them

    class TimingApplication(QApplication):
        recording = False

        def notify(self, receiver, event):  # noqa: D102
            if not TimingApplication.recording:
                return super().notify(receiver, event)
            kind = event.type()
            key = (getattr(kind, "name", str(kind)), type(receiver).__name__)
            nested.append(0.0)
            nested_cpu.append(0.0)
            t, c = time.perf_counter(), time.thread_time()
            out = super().notify(receiver, event)
            spent, spent_cpu = time.perf_counter() - t, time.thread_time() - c
            inner, inner_cpu = nested.pop(), nested_cpu.pop()
            if nested:
                nested[-1] += spent
                nested_cpu[-1] += spent_cpu
            total, own, own_cpu, count = times.get(key, (0.0, 0.0, 0.0, 0))
            times[key] = (total + spent, own + spent - inner, own_cpu + spent_cpu - inner_cpu, count + 1)
            return out

    TimingApplication(sys.argv[:1])
    times["_class"] = TimingApplication
    return times


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=REPO / "data" / "spk1_ta.tsv")
    parser.add_argument("--model", choices=("default", "artisynth", "block"), default="default")
    parser.add_argument("--modes", type=int, default=100)
    parser.add_argument("--seconds", type=float, default=5.0, help="playback time measured")
    parser.add_argument("--profile", action="store_true", help="print where playback spends its time")
    parser.add_argument("--profile-sort", default="cumulative", choices=("cumulative", "tottime"),
                        help="order of the profile: with what each function calls, or its own time")
    parser.add_argument("--no-context", action="store_true", help="without the transparent jaw and palate")
    parser.add_argument("--no-tabs", action="store_true", help="without the Energy, Morph and Segmentation tabs")
    parser.add_argument("--finish-views", action="store_true",
                        help="finish each view's drawing before the next (glFinish) so views_ms is each view's "
                             "whole cost (otherwise the rasterising is counted at the swap, outside the views)")
    parser.add_argument("--json", type=Path, help="write the figures to this JSON file")
    parser.add_argument("--screenshot", type=Path, help="save the window after playback (PNG)")
    parser.add_argument("--screenshot-time", type=float, default=5.6,
                        help="recording time (s from the start) the screenshot shows")
    parser.add_argument("--events", action="store_true", help="print the Qt events that take the time (by type and "
                                                                   "receiver; nested events are counted in their parents too)")
    args = parser.parse_args()

    from PySide6.QtCore import QEventLoop, QSettings, QTimer

    event_times = install_event_timer() if args.events else None

    from tonguevis.gui.app import application
    from tonguevis.gui.window import MainWindow
    from tonguevis.sim.settings import RunSettings

    application()  # the QApplication must exist before any widget
    try:
        model, label, landmarks = load_model(args.model)
    except Exception as exc:  # e.g. meshes/ not built yet
        print(f"model {args.model} not available ({exc}); using the ArtiSynth mesh")
        model, label, landmarks = load_model("artisynth")
    window = MainWindow(preferences=QSettings(str(Path("/tmp") / "tonguevis-bench.ini"), QSettings.Format.IniFormat),
                        run_settings=RunSettings(modes=args.modes))
    window.model, window.landmarks = model, landmarks
    if not args.no_tabs:
        from tonguevis.gui.tabs import add_feature_tabs

        add_feature_tabs(window)
    window.resize(1500, 950)
    window.show()

    # Wait in local event loops: app.quit() would close pyvistaqt's plotter (aboutToQuit),
    # and a busy processEvents() loop leaks references to None in PySide6.
    loop = QEventLoop()
    done = {}

    def finished(ok: bool) -> None:
        done["ok"] = ok
        loop.quit()

    def wait(seconds: float) -> None:
        QTimer.singleShot(int(1000 * seconds), loop.quit)
        loop.exec()

    window.simulation_finished.connect(finished)
    t0 = time.perf_counter()
    window.open_recording(args.recording)
    loop.exec()  # until the simulation finishes
    prep = time.perf_counter() - t0
    if not done.get("ok"):
        print("simulation failed:", window.statusBar().currentMessage())
        return 1
    if args.no_context:
        window.view3d.set_context_visible(False)
    session = window.session
    frames = session.frames
    state = window.state
    state.set_time(state.start + 5.0)
    wait(1.5)  # the plots' first draws (draw_idle after the simulation) are not playback's

    timings = Timings(window, finish_views=args.finish_views)
    load_before = os.getloadavg()
    start_frame = window.view3d.renders
    ticks0 = window.playback.ticks
    xpid = x_server_pid()
    t0, c0, x0 = time.perf_counter(), time.process_time(), cpu_seconds(xpid)
    threads0 = thread_cpu_seconds()
    timings.reset()
    if event_times is not None:
        event_times.pop("_class").recording = True
    state.set_playing(True)
    if os.environ.get("TONGUEVIS_BENCH_ANNOUNCE"):  # for an external profiler (perf record -p PID)
        print(f"playback starts, pid {os.getpid()}", flush=True)
    profiler = None
    if args.profile:
        import cProfile

        profiler = cProfile.Profile()
        profiler.enable()
    QTimer.singleShot(int(1000 * args.seconds), loop.quit)
    from tonguevis.appstate import connected

    unsubscribe = connected(state.events.playing, lambda e: None if e.value else loop.quit())
    loop.exec()
    unsubscribe()
    if event_times is not None:
        top = sorted(event_times.items(), key=lambda kv: -kv[1][1])[:20]
        per = 1e3 / max(window.view3d.renders - start_frame, 1)
        print("Qt events during playback (ms per drawn frame: own time, the GUI thread's CPU in it, with nested "
              "events; count):")
        for (kind, receiver), (total, own, own_cpu, count) in top:
            print(f"  {kind:<28} {receiver:<32} {per * own:8.2f} ms {per * own_cpu:8.2f} ms CPU {per * total:8.2f} ms"
                  f"  {count}")
    if profiler is not None:
        profiler.disable()
        import pstats

        pstats.Stats(profiler).sort_stats(args.profile_sort).print_stats(int(os.environ.get("TONGUEVIS_BENCH_PROFILE_LINES", "30")))
    wall, cpu, x_cpu = time.perf_counter() - t0, time.process_time() - c0, cpu_seconds(xpid) - x0
    threads1 = thread_cpu_seconds()
    state.set_playing(False)
    load_after = os.getloadavg()
    drawn = window.view3d.renders - start_frame
    ticks = window.playback.ticks - ticks0

    n = max(drawn, 1)
    frame_ms = 1e3 * wall / n
    render_ms = 1e3 * timings.render / n
    update_ms = 1e3 * timings.update / n
    readback_ms = 1e3 * timings.readback / n
    views_ms = dict(zip(timings.view_names, np.round(1e3 * timings.views / n, 2).tolist()))
    lags = 1e3 * np.asarray(timings.lags) if timings.lags else np.zeros(1)
    results = {
        "fps": drawn / wall,
        "frame_ms": frame_ms,
        "render_ms": render_ms,
        "render_cpu_ms": 1e3 * timings.render_cpu / n,
        "views_ms": views_ms,
        "views_finished": args.finish_views,
        "swap_ms": render_ms - float(sum(views_ms.values())),
        "update_ms": update_ms,
        "readback_ms": readback_ms,
        "readback_cpu_ms": 1e3 * timings.readback_cpu / n,
        "other_ms": frame_ms - render_ms - update_ms - readback_ms,
        "cpu_ms": 1e3 * cpu / n,
        "x_server_cpu_ms": 1e3 * x_cpu / n if xpid is not None else None,
        "threads_cpu_ms": {name: round(1e3 * (threads1[name] - threads0.get(name, 0.0)) / n, 1)
                           for name in threads1 if threads1[name] - threads0.get(name, 0.0) > 0},
        "fps_cpu_bound": 1000.0 / max(1e3 * cpu / n, 1e-9),
        "renders_per_frame": timings.renders / n,
        "plot_draws": timings.plot_draws,
        "lag_ms": {"mean": float(lags.mean()), "max": float(lags.max())},
        "frames_drawn": drawn,
        "clock_ticks": ticks,
        "seconds": wall,
        "context_shown": not args.no_context,
        "tabs": not args.no_tabs,
        "load_average": {"before": list(load_before), "after": list(load_after)},
        "cpus": os.cpu_count(),
        "gl_renderer": gl_renderer(window.view3d.plotter.render_window),
        "view_pixels": [window.view3d.plotter.interactor.width(), window.view3d.plotter.interactor.height()],
        "model": f"{label}, {model.mesh.n_nodes} nodes, {model.mesh.n_tets} tets, {args.modes} modes",
        "recording": f"{args.recording.name}, {frames.n_frames} frames",
        "clock": window.statusBar().currentMessage(),
        "commit": commit(),
    }
    print(f"model: {results['model']}")
    print(f"recording: {results['recording']}; open + simulate + precompute: {prep:.2f} s")
    print(f"clock: {results['clock']}; GL: {results['gl_renderer']}; 3D widget {results['view_pixels']} px")
    print(f"load average {load_before[0]:.2f} before, {load_after[0]:.2f} after, on {os.cpu_count()} CPUs")
    print(f"playback: {drawn} frames drawn in {wall:.2f} s = {drawn / wall:.1f} frames/s ({frame_ms:.1f} ms per frame"
          f", {ticks} clock ticks), jaw and palate {'hidden' if args.no_context else 'shown'}")
    print(f"  per frame: VTK render {render_ms:.1f} ms ({results['render_cpu_ms']:.1f} ms CPU; "
          + ", ".join(f"{k} {v:.1f}" for k, v in views_ms.items())
          + f", outside the views (blit, swap{'' if args.finish_views else ', rasterising'}) {results['swap_ms']:.1f}"
          + f"; {results['renders_per_frame']:.2f} renders per frame), buffer update {update_ms:.2f} ms, "
            f"read-back (rasterising left + copy) {readback_ms:.1f} ms ({results['readback_cpu_ms']:.1f} ms CPU), "
            f"other (Qt, cursors, labels) {results['other_ms']:.1f} ms")
    print(f"  CPU per frame {results['cpu_ms']:.1f} ms (all threads) -> {results['fps_cpu_bound']:.1f} frames/s "
          f"if the process had the CPU it uses; the X server {results['x_server_cpu_ms'] or 0:.1f} ms CPU per frame; "
          f"full plot redraws during playback: {timings.plot_draws}")
    print("  CPU per frame by thread: " + ", ".join(f"{k} {v:.1f} ms" for k, v in results["threads_cpu_ms"].items()))
    print(f"  painted frame behind the clock (negative: ahead): mean {results['lag_ms']['mean']:.1f} ms, max {results['lag_ms']['max']:.1f} ms")
    if args.screenshot is not None:
        # At a fixed time (the first syllable's closure), so that pictures of two versions compare.
        state.set_time(state.start + args.screenshot_time)
        wait(1.0)
        window.export_screenshot(os.fspath(args.screenshot))
        print(f"wrote {args.screenshot}")
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.json}")
    window.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
