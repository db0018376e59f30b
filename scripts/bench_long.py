#!/usr/bin/env python
"""Benchmark long recordings: peak memory and wall time against the recording's length.

For each length M (minutes) the demo /ta/ (``data/spk1_ta.tsv`` and its WAV) is
tiled into an M-minute NDI Wave recording in a temporary folder (deleted
afterwards, never committed), and each measurement runs in its own child
process so that its peak resident memory (``ru_maxrss``) is its own:

- ``integrate``: the pure simulation, for reference: targets, the drive
  schedule and the compiled Newmark frame loop (no mesh reconstruction);
- ``simulate``: ``tonguevis simulate FILE``;
- ``simulate_npz``: ``tonguevis simulate FILE --out DIR`` (what ``--out`` writes
  by default in the version measured), with the bytes and files written;
- ``simulate_paraview``: the ParaView export (``--out DIR --paraview`` where it
  exists, and ``simulate_paraview_surface`` with ``--surface-only``; before it,
  ``--out`` itself wrote the per-frame ``.vtu`` series);
- ``view``: the app headless (Xvfb): create the window, open the recording,
  wait for the first tongue frame drawn (``first_frame_s``; a long recording's
  first seconds are drawn while the rest simulates: ``first_frame_preview``),
  then for the whole motion (``whole_motion_s``); then 200 steps of playback
  and 50 random seeks, each drawn, as milliseconds per frame.

The same script runs on any checkout (it puts its own repository first on
the children's ``PYTHONPATH``), so ``git worktree add /tmp/before COMMIT`` and a
copy of this script give the figures before a change.  Growth with length is
then a ratio within one run: ``--json`` writes every figure and the ratios of
each length to the shortest.

    nice python scripts/bench_long.py --minutes 1 5 30 --json long.json
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "data" / "spk1_ta.tsv"
CHILD_TIMEOUT = 4 * 3600


# ---------------------------------------------------------------------------- the recording
def make_recording(minutes: float, folder: Path) -> Path:
    """The demo /ta/ tiled to ``minutes`` (NDI Wave TSV + WAV + sensor map) in ``folder``."""
    import numpy as np
    from scipy.io import wavfile

    lines = DEMO.read_text().splitlines()
    header, rows = lines[0], [line.split("\t") for line in lines[1:] if line.strip()]
    period = len(rows)
    dt = float(rows[1][0]) - float(rows[0][0])
    wav_step = float(rows[1][2]) - float(rows[0][2])
    total = max(2, int(round(minutes * 60.0 / dt)))
    out = folder / f"long_{minutes:g}min.tsv"
    with open(out, "w") as fh:
        fh.write(header + "\n")
        for k in range(total):
            tile, row = divmod(k, period)
            fields = list(rows[row])
            fields[0] = f"{k * dt:.6f}"
            fields[1] = f"{k + 1:.6f}"
            fields[2] = f"{k * wav_step:.6f}"
            fh.write("\t".join(fields) + "\n")
    rate, samples = wavfile.read(DEMO.with_suffix(".wav"))
    per_tile = int(round(period * dt * rate))
    tile = samples[:per_tile]
    if len(tile) < per_tile:
        tile = np.concatenate([tile, np.zeros(per_tile - len(tile), dtype=tile.dtype)])
    n_audio = int(round(total * dt * rate))
    wavfile.write(out.with_suffix(".wav"), rate, np.resize(tile, n_audio))
    shutil.copy(DEMO.parent / "sensor_map.json", folder / "sensor_map.json")
    return out


def folder_bytes(folder: Path) -> tuple[int, int]:
    """(bytes, files) under ``folder``."""
    size = files = 0
    for path in folder.rglob("*"):
        if path.is_file():
            size += path.stat().st_size
            files += 1
    return size, files


# ---------------------------------------------------------------------------- children
def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def child_integrate(file: Path) -> dict:
    import numpy as np

    from tonguevis.sim import TongueModel
    from tonguevis.sim.newmark import NewmarkSettings
    from tonguevis.sim.newmark_kernel import integrate_compiled
    from tonguevis.sim.simulate import DEFAULT_SENSOR_STIFFNESS, drive_schedule
    from tonguevis.preprocess.targets import prepare_targets
    from tonguevis.workflows import open_recording

    from tonguevis._backend import prepare_kernels

    prepare_kernels()  # loading the compiled frame loop is not simulating
    t0 = time.perf_counter()
    recording = open_recording(file)
    t_read = time.perf_counter() - t0
    model = TongueModel.default()
    basis = model.basis(100)
    t1 = time.perf_counter()
    prep = prepare_targets(recording, model)
    t_prep = time.perf_counter() - t1
    w_full = model.rotation_matrix(basis)
    dofs = (3 * prep.nodes[:, None] + np.arange(3)).ravel()
    s = len(prep.nodes)
    phi_s, w_s = basis.phi[dofs].reshape(s, 3, -1), w_full[dofs].reshape(s, 3, -1)
    settings = NewmarkSettings(dt=1.0 / recording.rate, alpha=model.material.alpha, beta=model.material.beta,
                               tolerance=1e-8, warping=True)
    t2 = time.perf_counter()
    targets, compliance, schedule = drive_schedule(prep.displacement, recording.rate, basis.eigenvalues, phi_s,
                                                   DEFAULT_SENSOR_STIFFNESS)
    t3 = time.perf_counter()
    result = integrate_compiled(basis.eigenvalues, phi_s, w_s, targets, settings, compliance=compliance)
    t4 = time.perf_counter()
    return {"frames": int(len(result.q)), "read_s": t_read, "prepare_s": t_prep, "drive_schedule_s": t3 - t2,
            "integrate_s": t4 - t3, "pure_simulation_s": t4 - t2, "peak_mb": _peak_mb()}


def child_cli(argv: list[str]) -> dict:
    import contextlib
    import io

    from tonguevis.cli import main

    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()) as out:
        code = main(argv)
    return {"wall_s": time.perf_counter() - t0, "exit": int(code), "peak_mb": _peak_mb(),
            "output_tail": out.getvalue().strip().splitlines()[-1:]}


def child_view(file: Path, started: float) -> dict:
    import numpy as np
    from PySide6.QtCore import QTimer

    from tonguevis.gui.app import application, create_window

    app = application()
    result: dict = {}
    window = create_window(file, feature_tabs=True)
    rng = np.random.default_rng(0)

    def first_frame_drawn() -> bool:
        view = window.view3d
        return (window.session is not None and window.session.frames is not None and view.renders > 0)

    def first_frame() -> None:
        # A long recording's first seconds are drawn before the rest is simulated: that is the first frame.
        window.view3d.plotter.render()
        result["first_frame_s"] = time.perf_counter() - started
        result["peak_mb_at_first_frame"] = _peak_mb()
        motion = window.session.frames.motion
        result["first_frame_of_frames"] = int(motion.n_frames)
        result["first_frame_preview"] = "preview" in motion.metadata

    def measure() -> None:
        # Playback and seeking on the whole motion, once it is simulated.
        view, state = window.view3d, window.state
        view.plotter.render()
        result["whole_motion_s"] = time.perf_counter() - started
        frames = window.session.frames
        n = frames.n_frames
        start = frames.frame_at(state.time)
        timings = {}
        for name, picks in (("playback", (start + np.arange(1, 201)) % n), ("seek", rng.integers(0, n, 50))):
            t0 = time.perf_counter()
            for i in picks:
                state.set_time(float(frames.times[int(i)]))
                view.plotter.render()
            timings[name] = 1e3 * (time.perf_counter() - t0) / len(picks)
        result["frame_ms_playback"] = timings["playback"]
        result["frame_ms_seek"] = timings["seek"]
        result["frames"] = int(n)
        result["peak_mb"] = _peak_mb()
        window.close()
        app.exit(0)

    finished = []

    def poll() -> None:
        if "first_frame_s" not in result and first_frame_drawn():
            first_frame()
        if "first_frame_s" in result and finished:
            timer.stop()
            QTimer.singleShot(0, measure)

    def failed(ok: bool) -> None:
        if not ok:
            result["error"] = window.statusBar().currentMessage() or "simulation failed"
            app.exit(1)
        finished.append(ok)

    window.simulation_finished.connect(failed)
    timer = QTimer()
    timer.setInterval(20)
    timer.timeout.connect(poll)
    timer.start()
    app.exec()
    return result


def run_child(kind: str, args: list[str], env: dict, tmp: Path, max_rss_gb: float) -> dict:
    """Run one measurement in a child process; a child whose resident memory passes
    ``max_rss_gb`` is stopped (the machine is shared) and reported as such."""
    out = tmp / f"child-{kind}-{time.monotonic_ns()}.json"
    log = tmp / f"child-{kind}.log"
    command = [sys.executable, str(Path(__file__).resolve()), "--child", kind, "--child-out", str(out), "--", *args]
    t0 = time.perf_counter()
    with open(log, "w") as fh:
        proc = subprocess.Popen(command, env=env, stdout=fh, stderr=subprocess.STDOUT)
        peak = 0.0
        while proc.poll() is None:
            rss = _rss_mb(proc.pid)
            peak = max(peak, rss)
            if rss > 1024 * max_rss_gb or time.perf_counter() - t0 > CHILD_TIMEOUT:
                proc.kill()
                proc.wait()
                return {"stopped": f"resident memory passed {max_rss_gb:g} GB" if rss > 1024 * max_rss_gb
                        else "timeout", "peak_mb_at_least": round(peak), "after_s": round(time.perf_counter() - t0, 1)}
            time.sleep(0.2)
    wall = time.perf_counter() - t0
    if proc.returncode != 0 or not out.exists():
        return {"error": log.read_text().strip()[-2000:], "process_wall_s": wall}
    data = json.loads(out.read_text())
    data["process_wall_s"] = wall
    return data


def _rss_mb(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


# ---------------------------------------------------------------------------- parent
def supports(env: dict, flag: str) -> bool:
    proc = subprocess.run([sys.executable, "-m", "tonguevis", "simulate", "--help"], env=env, capture_output=True,
                          text=True)
    return flag in proc.stdout


def start_display() -> tuple[subprocess.Popen | None, str | None]:
    """An Xvfb of our own for the app (killed by its pid at the end)."""
    if shutil.which("Xvfb") is None:
        return None, None
    for number in range(91, 120):
        if not Path(f"/tmp/.X11-unix/X{number}").exists() and not Path(f"/tmp/.X{number}-lock").exists():
            proc = subprocess.Popen(["Xvfb", f":{number}", "-screen", "0", "1600x1000x24", "-nolisten", "tcp"],
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            time.sleep(1.0)
            if proc.poll() is None:
                return proc, f":{number}"
    return None, None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[1.0, 5.0, 30.0])
    parser.add_argument("--json", type=Path, help="write every figure here")
    parser.add_argument("--only", nargs="+", choices=("integrate", "simulate", "simulate_npz", "simulate_paraview",
                                                       "view"), help="run only these measurements")
    parser.add_argument("--vtk-series-max-minutes", type=float, default=5.0,
                        help="the old one-.vtu-per-frame export is skipped above this length (about 1.3 GB and "
                             "1.6 min per recorded minute); its bytes grow exactly with the frames")
    parser.add_argument("--max-rss-gb", type=float, default=6.0,
                        help="stop a measurement whose resident memory passes this (default 6 GB: the machine "
                             "is shared); it is reported as stopped, with the memory it had reached")
    parser.add_argument("--no-demo", action="store_true", help="skip the app on the demo itself (the reference "
                                                               "for playback and seeking)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--child-out", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("child_args", nargs="*", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.child:
        started = time.perf_counter()
        if args.child == "integrate":
            data = child_integrate(Path(args.child_args[0]))
        elif args.child == "cli":
            data = child_cli(args.child_args)
        else:
            data = child_view(Path(args.child_args[0]), started)
        args.child_out.write_text(json.dumps(data))
        return 0

    commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "tonguevis"], capture_output=True,
                                text=True).stdout.strip())
    tmp = Path(tempfile.mkdtemp(prefix="tonguevis-bench-long-"))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["TONGUEVIS_CACHE"] = str(tmp / "cache")
    env.setdefault("QT_QPA_PLATFORM", "xcb")
    paraview = supports(env, "--paraview")
    wanted = set(args.only or ("integrate", "simulate", "simulate_npz", "simulate_paraview", "view"))
    xvfb, display = (None, None)
    if "view" in wanted and env["QT_QPA_PLATFORM"] == "xcb":
        xvfb, display = start_display()
        if display:
            env["DISPLAY"] = display
    report = {"repository": str(REPO), "commit": commit + ("+changes" if dirty else ""),
              "paraview_export": "--out DIR --paraview (XDMF + HDF5)" if paraview else
              "--out DIR (one .vtu per frame + .pvd)", "cpu_count": os.cpu_count(), "lengths": {}}
    try:
        # Warm-up: the modal basis cache and warp's kernels, so no measurement pays for them.
        warm = make_recording(0.1, tmp)
        run_child("cli", ["simulate", str(warm), "--quiet"], env, tmp, args.max_rss_gb)
        if "view" in wanted and not args.no_demo and env.get("DISPLAY"):
            report["demo_view"] = run_child("view", [str(DEMO)], env, tmp, args.max_rss_gb)
            print("demo view", report["demo_view"], flush=True)
        for minutes in args.minutes:
            folder = tmp / f"rec-{minutes:g}"
            folder.mkdir()
            file = make_recording(minutes, folder)
            row: dict = {"minutes": minutes, "recording_mb": round(file.stat().st_size / 2**20, 1)}
            print(f"--- {minutes:g} min ({file.stat().st_size / 2**20:.0f} MB TSV)", flush=True)
            if "integrate" in wanted:
                row["integrate"] = run_child("integrate", [str(file)], env, tmp, args.max_rss_gb)
                print("  integrate", row["integrate"], flush=True)
            if "simulate" in wanted:
                row["simulate"] = run_child("cli", ["simulate", str(file), "--quiet"], env, tmp, args.max_rss_gb)
                print("  simulate", row["simulate"], flush=True)
            exports = []
            if "simulate_npz" in wanted and paraview:
                exports.append(("simulate_npz", []))
            if "simulate_paraview" in wanted:
                if paraview:
                    exports.append(("simulate_paraview", ["--paraview"]))
                    exports.append(("simulate_paraview_surface", ["--paraview", "--surface-only"]))
                elif minutes <= args.vtk_series_max_minutes:
                    exports.append(("simulate_paraview", []))
                else:
                    row["simulate_paraview"] = {"skipped": f"one .vtu per frame above "
                                                           f"{args.vtk_series_max_minutes:g} min"}
            for name, extra in exports:
                out = folder / f"out-{name}"
                data = run_child("cli", ["simulate", str(file), "--quiet", "--out", str(out), *extra], env, tmp,
                                 args.max_rss_gb)
                if out.exists():
                    data["bytes"], data["files"] = folder_bytes(out)
                    shutil.rmtree(out, ignore_errors=True)
                row[name] = data
                print(f"  {name}", data, flush=True)
            if "view" in wanted:
                row["view"] = run_child("view", [str(file)], env, tmp, args.max_rss_gb) if env.get("DISPLAY") or \
                    env["QT_QPA_PLATFORM"] != "xcb" else {"skipped": "no display (Xvfb not found)"}
                print("  view", row["view"], flush=True)
            report["lengths"][f"{minutes:g}"] = row
            shutil.rmtree(folder, ignore_errors=True)
    finally:
        if xvfb is not None:
            xvfb.terminate()
            xvfb.wait(10)
        shutil.rmtree(tmp, ignore_errors=True)
    report["growth"] = growth(report["lengths"])
    text = json.dumps(report, indent=2)
    if args.json:
        args.json.write_text(text + "\n")
    print(text)
    return 0


def growth(lengths: dict) -> dict:
    """Each length's figures as ratios to the shortest length's (memory flat = ratio near 1)."""
    keys = sorted(lengths, key=float)
    if len(keys) < 2:
        return {}
    base = lengths[keys[0]]
    out = {}
    for key in keys[1:]:
        row, ratios = lengths[key], {}
        for name, value in row.items():
            if not isinstance(value, dict):
                continue
            for figure in ("peak_mb", "wall_s", "pure_simulation_s", "first_frame_s", "bytes"):
                a, b = base.get(name, {}).get(figure), value.get(figure)
                if isinstance(a, (int, float)) and isinstance(b, (int, float)) and a:
                    ratios[f"{name}.{figure}"] = round(b / a, 2)
        out[f"{key} / {keys[0]}"] = ratios
    return out


if __name__ == "__main__":
    sys.exit(main())
