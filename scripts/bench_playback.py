#!/usr/bin/env python
"""Playback frame rate of the desktop app under Xvfb (or any display), and the
simulation's share of each frame.

Opens the real window on a demo recording, simulates it, then plays for a few
seconds and counts frames drawn (3D render of the four views + plot cursors).
Prints frames per second, the mean time per frame split into: copying the
precomputed frame into the render buffers, VTK render, and the rest (Qt,
plot cursors); and what computing a frame from q on demand would cost
(``model.displacements`` of one frame, the per-frame simulation work).

Run: xvfb-run -a -s "-screen 0 1600x1000x24" python scripts/bench_playback.py [--seconds 5] [--modes 100]
"""

from __future__ import annotations

import argparse
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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=REPO / "data" / "spk1_ta.tsv")
    parser.add_argument("--model", choices=("default", "artisynth", "block"), default="default")
    parser.add_argument("--modes", type=int, default=100)
    parser.add_argument("--seconds", type=float, default=5.0, help="playback time measured")
    parser.add_argument("--profile", action="store_true", help="print where playback spends its time")
    parser.add_argument("--no-context", action="store_true", help="without the transparent jaw and palate")
    args = parser.parse_args()

    from PySide6.QtCore import QSettings

    from tonguevis.gui.app import application
    from tonguevis.gui.scene import TongueScene
    from tonguevis.gui.window import MainWindow

    application()  # the QApplication must exist before any widget
    if args.no_context:
        import tonguevis.gui.view3d as view3d

        view3d.context_surfaces = lambda: {}
    try:
        model, label, landmarks = load_model(args.model)
    except Exception as exc:  # e.g. meshes/ not built yet
        print(f"model {args.model} not available ({exc}); using the ArtiSynth mesh")
        model, label, landmarks = load_model("artisynth")
    window = MainWindow(settings=QSettings(str(Path("/tmp") / "tonguevis-bench.ini"), QSettings.Format.IniFormat),
                        modes=args.modes)
    window.model, window.landmarks = model, landmarks
    window.resize(1500, 950)
    window.show()
    from PySide6.QtCore import QEventLoop, QTimer

    # Wait in local event loops: app.quit() would close pyvistaqt's plotter (aboutToQuit),
    # and a busy processEvents() loop leaks references to None in PySide6.
    loop = QEventLoop()
    done = {}

    def finished(ok: bool) -> None:
        done["ok"] = ok
        loop.quit()

    window.simulation_finished.connect(finished)
    t0 = time.perf_counter()
    window.open_recording(args.recording)
    loop.exec()  # until the simulation finishes
    prep = time.perf_counter() - t0
    if not done.get("ok"):
        print("simulation failed:", window.statusBar().currentMessage())
        return 1
    session = window.session
    frames = session.frames

    # Time the VTK renders (observers on the render window) and the buffer updates.
    scene = window.view3d.scene
    timings = {"update": 0.0, "render": 0.0, "count": 0, "renders": 0, "_t": 0.0}
    original_update = TongueScene.update

    def timed_update(self, *a, **k):
        t = time.perf_counter()
        original_update(self, *a, **k)
        timings["update"] += time.perf_counter() - t
        timings["count"] += 1

    def render_start(*_):
        timings["_t"] = time.perf_counter()

    def render_end(*_):
        timings["render"] += time.perf_counter() - timings["_t"]
        timings["renders"] += 1

    scene.update = timed_update.__get__(scene)
    render_window = window.view3d.plotter.render_window
    render_window.AddObserver("StartEvent", render_start)
    render_window.AddObserver("EndEvent", render_end)
    state = window.state
    state.set_time(state.start + 5.0)
    start_frame = window.view3d.renders
    t0 = time.perf_counter()
    timings.update(render=0.0, renders=0, update=0.0, count=0)
    state.set_playing(True)
    profiler = None
    if args.profile:
        import cProfile

        profiler = cProfile.Profile()
        profiler.enable()
    QTimer.singleShot(int(1000 * args.seconds), loop.quit)
    state.subscribe("playing", lambda e: None if e.value else loop.quit())
    loop.exec()
    if profiler is not None:
        profiler.disable()
        import pstats

        pstats.Stats(profiler).sort_stats("tottime").print_stats(15)
    state.set_playing(False)
    wall = time.perf_counter() - t0
    drawn = window.view3d.renders - start_frame

    # The simulation's per-frame cost if frames were computed on demand.
    q = session.motion.q
    picks = np.linspace(0, len(q) - 1, 50).astype(int)
    model.displacements(q[picks[:1]], warping=True, dtype=np.float32)
    t = time.perf_counter()
    for i in picks:
        model.displacements(q[i : i + 1], warping=True, dtype=np.float32)
    on_demand = (time.perf_counter() - t) / len(picks)

    n = max(timings["count"], 1)
    frame_ms = 1e3 * wall / max(drawn, 1)
    print(f"model: {label}, {model.mesh.n_nodes} nodes, {model.mesh.n_tets} tets, {args.modes} modes")
    print(f"recording: {args.recording.name}, {frames.n_frames} frames; open + simulate + precompute: {prep:.2f} s")
    print(f"clock: {window.statusBar().currentMessage()}")
    print(f"playback: {drawn} frames drawn in {wall:.2f} s = {drawn / wall:.1f} frames/s ({frame_ms:.1f} ms per frame)")
    print(f"  per frame: buffer update (copy precomputed points/scalars + normals) {1e3 * timings['update'] / n:.2f} ms, "
          f"VTK render of the four views {1e3 * timings['render'] / max(timings['renders'], 1):.1f} ms "
          f"({timings['renders'] / n:.2f} renders per frame), "
          f"rest (Qt events, plot cursors) {frame_ms - 1e3 * (timings['update'] + timings['render']) / n:.1f} ms")
    print(f"  simulation share: precomputed, so {100 * timings['update'] / max(wall, 1e-9) * drawn / n:.1f} % of the frame "
          f"time is the per-frame copy; computing a frame from q on demand would cost {1e3 * on_demand:.2f} ms "
          f"({100 * 1e3 * on_demand / frame_ms:.1f} % of a frame)")
    window.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
