#!/usr/bin/env python
"""Benchmark ``tonguevis batch``: recordings per minute with 1 and 2 workers on the same corpus, in one run.

Generates a synthetic corpus (``make_demo_data.py --speakers N --trains K``,
in a temporary folder unless ``--corpus`` names one), then runs the batch on it
with each worker count of ``--workers`` into a fresh output folder each (so
nothing is "up to date"), all in this one run, on the shipped tongue with 100
modes, and reports per count: recordings per minute, wall time and its parts
(model, plan, prepare, run, gather), the workers' start-up, CPU seconds per recording in the workers, the
largest resident memory per worker, and the machine's load average. The
scaling is the ratio of recordings per minute, 2 workers over 1. From the
measured parts it projects a corpus of 10,000 recordings on a 100-core cluster
and says what bounds it. Speed goals are checked here, never in timed tests.

With ``--slurm N`` it also runs the corpus on N single-core SLURM jobs (``tonguevis batch --slurm
--slurm-jobs N``; a running SLURM: ``scripts/slurm_local.sh start``) and compares it with the local
run of as many workers.

    python scripts/bench_batch.py --json bench_batch.json
    python scripts/bench_batch.py --speakers 25 --steps simulate,energy --json bench_energy.json
    python scripts/bench_batch.py --workers 2 --slurm 2 --json bench_slurm.json
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def step_seconds(out: Path) -> dict[str, float]:
    """Mean seconds per recording of each step, from the manifests."""
    totals: dict[str, list[float]] = {}
    for manifest in (out / "recordings").rglob("manifest.json"):
        for step, entry in json.loads(manifest.read_text()).get("steps", {}).items():
            totals.setdefault(step, []).append(entry["seconds"])
    return {step: sum(v) / len(v) for step, v in totals.items()}


def projection(runs: list[dict], n: int = 10_000, cores: int = 100) -> dict:
    """10,000 recordings on 100 cores, on paper, from the one-worker run's parts."""
    one = runs[0]
    per = one["cpu_s_per_recording"]  # a core's work per recording, in process, least contended
    compute = math.ceil(n / cores) * per
    # serial, in the client; the least of the runs (the first pays for imports)
    plan = min(r["timings_s"]["plan"] / r["recordings"] for r in runs) * n
    gather = min(r["timings_s"]["gather"] / r["recordings"] for r in runs) * n
    startup = max(r["worker_startup_s"] for r in runs)
    files_written = one["files_per_recording"] * n
    bounds = {
        "compute on the workers (ceil(N / cores) x CPU s per recording)": compute,
        "planning in the client: hashing every input, reading the manifests (serial)": plan,
        "gathering the corpus tables in the client (serial)": gather,
        "compilation and start: warp kernels once (~12 s when the cache is cold), model and basis once, "
        "each worker importing and loading them (in parallel)":
            12.0 + one["timings_s"]["model"] + one["timings_s"]["prepare"] + startup,
        "scheduling: Dask's ~1 ms per task on the scheduler": 1e-3 * n,
    }
    return {
        "recordings": n, "cores": cores,
        "estimated_s": sum(bounds.values()),
        "parts_s": bounds,
        "bound_by": max(bounds, key=bounds.get),
        "files_written": files_written,
        "output_gb": one["output_mb_per_recording"] * n / 1024,
        "note": ("Compute scales with the cores as long as each worker has a core of its own: on this 2-core "
                 "machine shared with other jobs it does not. The client's planning and gathering are serial "
                 "and grow with N; on a shared file system the ~%d small files per recording (manifest, tables, "
                 "motion; temporary name then rename) load its metadata server: %d file creations in all."
                 % (one["files_per_recording"], files_written)),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speakers", type=int, default=4, help="synthetic speakers (x4 syllables; default 4)")
    parser.add_argument("--trains", type=int, default=1, help="five-syllable trains per recording (default 1)")
    parser.add_argument("--corpus", type=Path, help="use this corpus instead of generating one")
    parser.add_argument("--steps", default="simulate,energy,segment")
    parser.add_argument("--segment-first", type=int, default=1, help="productions segmented per recording")
    parser.add_argument("--modes", type=int, default=100)
    parser.add_argument("--workers", default="1,2", help="worker counts to compare (default 1,2)")
    parser.add_argument("--slurm", type=int, metavar="N", help="also on N single-core SLURM jobs")
    parser.add_argument("--slurm-profile", type=Path, metavar="TOML", help="the SLURM jobs' profile (--slurm)")
    parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args(argv)

    workdir = Path(tempfile.mkdtemp(prefix="tonguevis-bench-batch-"))
    os.environ.setdefault("TONGUEVIS_CACHE", str(workdir / "cache"))
    corpus = args.corpus
    if corpus is None:
        corpus = workdir / "corpus"
        subprocess.run([sys.executable, str(REPO / "scripts" / "make_demo_data.py"), "--speakers",
                        str(args.speakers), "--trains", str(args.trains), "--out", str(corpus)],
                       check=True, stdout=subprocess.DEVNULL)
    from tonguevis.batch import run

    counts = [int(w) for w in args.workers.split(",")]
    plans = [(jobs, f"out-{jobs}", {"workers": jobs}) for jobs in counts]
    if args.slurm:
        from tonguevis.batch.slurm import SlurmOptions

        slurm = (SlurmOptions.from_profile(args.slurm_profile, jobs=args.slurm, cores=1) if args.slurm_profile
                 else SlurmOptions(jobs=args.slurm, cores=1))
        plans.append((args.slurm, "out-slurm", {"workers": slurm}))
    runs = []
    for jobs, folder, where in plans:
        out = workdir / folder
        load = os.getloadavg()
        finished: list[float] = []

        def progress(done, total, message, finished=finished):
            finished.append(time.perf_counter())

        started = time.perf_counter()
        result = run(corpus, out, **where, steps=args.steps, modes=args.modes, segment_first=args.segment_first,
                     progress=progress)
        if not result.ok:
            print(f"{len(result.failures)} recording(s) failed: {result.failures[:3]}", file=sys.stderr)
        n = len(result.done)
        files = [p for p in (out / "recordings").rglob("*") if p.is_file()]
        worker_s = result.timings["run"]
        steps = step_seconds(out)
        # startup: the first result's delay beyond one recording's own time (imports, warp init, model, basis)
        running = started + sum(result.timings[k] for k in ("model", "plan", "prepare"))
        first = finished[1] - running if len(finished) > 1 else 0.0
        startup = max(0.0, first - sum(steps.values())) if jobs > 1 else 0.0
        figures = {
            "workers": jobs,
            "runner": ("in process" if jobs == 1 else f"loky, {jobs} processes") if "jobs" in where
            else f"SLURM, {jobs} single-core jobs (dask-jobqueue)",
            "recordings": n,
            "recordings_per_minute": 60.0 * n / result.seconds,
            "recordings_per_minute_steady": 60.0 * n / (worker_s - startup) if worker_s > startup else None,
            "wall_s": result.seconds,
            "timings_s": result.timings,
            "cpu_s_per_recording": result.cpu_seconds / max(n, 1),
            "step_s_per_recording": steps,
            "cpu_share_of_wall": result.cpu_seconds / (jobs * worker_s) if worker_s else None,
            "cores_used": result.cpu_seconds / worker_s if worker_s else None,
            "max_rss_mb_per_worker": sorted(result.workers.values()),
            "worker_startup_s": startup,
            "files_per_recording": len(files) / max(n, 1),
            "output_mb_per_recording": sum(p.stat().st_size for p in files) / 2**20 / max(n, 1),
            "load_average_before": load[0],
            "load_average_after": os.getloadavg()[0],
        }
        if "slurm" in where:
            figures["slurm"] = json.loads((out / "batch.json").read_text())["slurm"]
        runs.append(figures)
        print(f"{figures['runner']}: {n} recordings in {result.seconds:.1f} s = {figures['recordings_per_minute']:.1f} "
              f"recordings/min; CPU {figures['cpu_s_per_recording']:.2f} s per recording; workers' CPU share "
              f"of the running time {figures['cpu_share_of_wall']:.2f}; max RSS per worker "
              f"{', '.join(f'{m:.0f}' for m in figures['max_rss_mb_per_worker'])} MiB; load {load[0]:.1f}")
    slurm_run = runs.pop() if args.slurm else None
    report = {
        "corpus": {"path": str(corpus), "recordings": runs[0]["recordings"], "generated": args.corpus is None,
                   "speakers": args.speakers, "trains": args.trains},
        "steps": args.steps, "segment_first": args.segment_first, "modes": args.modes,
        "cores": os.cpu_count(), "runs": runs,
    }
    if len(runs) >= 2:
        report["ratio"] = runs[1]["recordings_per_minute"] / runs[0]["recordings_per_minute"]
        report["ratio_steady"] = runs[1]["recordings_per_minute_steady"] / runs[0]["recordings_per_minute_steady"]
        report["goal_ratio"] = 1.8
        two = runs[1]
        # what the same work would give with a free core per worker: the measured CPU per recording
        # (its growth is the workers' cost on each other: caches, memory bandwidth) and start-up
        report["estimated_ratio_free_cores"] = (
            counts[1] / counts[0] * runs[0]["cpu_s_per_recording"] / two["cpu_s_per_recording"]
            * (1.0 - two["worker_startup_s"] / two["wall_s"]))
        print(f"ratio {counts[1]} vs {counts[0]} workers: {report['ratio']:.2f} "
              f"({report['ratio_steady']:.2f} once the workers have started; goal >= 1.8); cores used "
              f"{runs[0]['cores_used']:.2f} vs {two['cores_used']:.2f}; with a free core per worker "
              f"~{report['estimated_ratio_free_cores']:.2f}")
    if slurm_run is not None:
        report["slurm"] = slurm_run
        local = next((r for r in runs if r["workers"] == args.slurm), None)
        if local is not None:
            report["slurm_vs_local"] = slurm_run["recordings_per_minute"] / local["recordings_per_minute"]
            print(f"SLURM, {args.slurm} single-core jobs vs {args.slurm} local workers: "
                  f"{slurm_run['recordings_per_minute']:.1f} vs {local['recordings_per_minute']:.1f} recordings/min "
                  f"({report['slurm_vs_local']:.2f}); SLURM's workers started "
                  f"{slurm_run['worker_startup_s']:.1f} s after the run began ({slurm_run['slurm']['version']})")
    report["projection"] = projection(runs)
    p = report["projection"]
    print(f"projection: {p['recordings']} recordings on {p['cores']} cores ~ {p['estimated_s'] / 60:.0f} min, "
          f"bound by {p['bound_by']}")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
