#!/usr/bin/env python
"""Seed 001's domains method (tonguevis.sim.domains) beside the modal methods, on whole recordings.

Per recording (the demo /ta/ and the shared real ones that are present: Opti-Speech /ta/ 009 and
the Haskins sentence), each method simulated over the whole trial, default settings:
frames/s of the whole ``simulate`` call (best of --repeat) and, for the domains, of its frame loop
alone and the exact forces it took a frame; the domains' frame loops side by side (``simulate_domains``
``scheme=``): "reference" (today's loop: NumPy force, Newton to 0.1 µm, the reference), the default
(compiled force, the previous frame's force carried to a first step, Newton to 1 µm), "linearised"
(one force a frame) and the cubature, each with its largest and RMS node displacement difference
from the reference over the trial (mm); the plausibility figures (far-field amplification, largest
volume change, sensor misfit), and, unless --no-validate, the held-out RMSE per tongue sensor: warped
and linear from :func:`tonguevis.analysis.validate`, the domains from
:func:`tonguevis.analysis.validation_domains.held_out_domains` (validate takes no method; the domains
are seeded at the driving sensors only).

    python scripts/bench_domains.py [--json OUT] [--no-validate] [--demo-only] [--recording I] [--repeat N]

Measured 2026-12-03, 2 cores shared with other sessions (load 2-3.5): best whole-call frames/s of two
runs (frame loop in brackets), forces a frame, largest / RMS node difference from the reference:
demo /ta/, 1,762 frames: warped 11,000, linear 23,600; domains reference 31 (36), 4.05 forces;
  domains (default) 511 (485), 1.64 forces, 0.003 / 0.0001 mm; linearised 509 (512), 0.06 / 0.002 mm;
  +cubature 523 (520), 0.52 / 0.07 mm.  (bench_simulation the same hour: domains_fps 678, loop 644.)
Opti-Speech /ta/ 009, 1,093 frames: warped 6,100, linear 10,600; domains reference 35 (42), 3.89 forces;
  default 401 (372), 2.54 forces, 0.12 / 0.004 mm; linearised 796 (829), 0.80 / 0.016 mm;
  +cubature 627 (820), 8.1 / 2.0 mm (the cubature's own error: the same with the reference loop).
Haskins sentence, 262 frames: warped 9,200, linear 13,400; domains reference 28 (30), 4.00 forces;
  default 312 (320), 2.89 forces, 0.21 / 0.008 mm; linearised 877 (979), 0.75 / 0.036 mm;
  +cubature 589 (873), 5.6 / 0.58 mm.
Before (this script, the same day): domains 21 / 31 / 15 frames/s whole call (loop 24 / 37 / 17).
What bounds the default: one exact force is two 5,406 × r BLAS products (r = 150: ~0.45 ms, the basis
streamed twice) and the 8,118-tet kernel (~0.3 ms), ~0.75 ms on one core; the loop costs ~0.1 ms a
frame more.  Converged to 1 µm a frame takes 1.6-2.9 forces, so 350-700 frames/s; 1,000 frames/s
needs at most one force a frame (the linearised scheme, up to 0.8 mm off) on an idle core.  Outside
the loop (caches warm) a call spends 0.03-0.1 s (7 s before, most of it the energies).  A second thread for the tet kernel gave nothing on the loaded cores (0.82
against 0.79 ms a force); threaded BLAS made a force 3.9 ms.  Tighter: tolerance 3e-7 m on 009 is
0.008 mm off at 3.1 forces a frame.
Held-out RMSE, mean over sensors (mm): Haskins warped 4.14, linear 4.11, kinematic 5.64, domains 4.20;
Opti-Speech /ta/ 009 warped 3.50, linear 3.48, kinematic 3.53, domains 3.72.

The machine's load changes the speed figures; run it alone.  Never commit the JSON of the
third-party recordings' figures per sample (only these summary figures).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data" / "ema"
RECORDINGS = [
    ("demo /ta/ (synthetic)", REPO / "data" / "spk1_ta.tsv"),
    ("Opti-Speech /ta/ 009", SHARED / "optispeech" / "009_OSN12_Tah_withFb_natural_HR.tsv"),
    ("Haskins sentence", SHARED / "mview" / "F01_B01_S01_R01_N.mat"),
]
METHODS = ("warped", "linear", "domains")


def run(name: str, path: Path, validate_too: bool, repeat: int = 3) -> dict:
    import numpy as np

    from tonguevis.sim import TongueModel
    from tonguevis.sim.simulate import simulate
    from tonguevis.workflows.recording import open_recording

    rec = open_recording(path)
    model = TongueModel.default()
    out = {"recording": name, "frames": int(rec.on_uniform_grid().n_samples), "rate_hz": float(rec.rate),
           "methods": {}}
    from tonguevis.sim.domains_run import simulate_domains

    variants = {  # the domains' frame loops (simulate_domains scheme=...), the reference first
        "domains reference": lambda: simulate_domains(rec, model, scheme="reference"),
        "domains": lambda: simulate(rec, model, method="domains"),
        "domains linearised": lambda: simulate_domains(rec, model, scheme="linearised"),
        "domains+cubature": lambda: simulate_domains(rec, model, cubature=True),
    }
    reference = None
    for method in METHODS[:2] + tuple(variants):
        run_it = variants.get(method) or (lambda: simulate(rec, model, method=method))
        run_it()  # the weights' (and cubature's) solve, caches and compiled kernels: the figure is the simulation's
        elapsed, motion = float("inf"), None
        for _ in range(1 if method == "domains reference" else repeat):  # best of ``repeat`` (the load varies)
            t0 = time.perf_counter()
            motion = run_it()
            elapsed = min(elapsed, time.perf_counter() - t0)
        p = motion.metadata["plausibility"]
        row = {"frames_per_s": motion.n_frames / elapsed, "seconds": elapsed,
               "amplification": p["amplification"], "volume_change_max_percent": p["volume_change_max_percent"],
               "sensor_misfit_rms_mm": p["sensor_misfit_rms_mm"], "sensor_misfit_max_mm": p["sensor_misfit_max_mm"],
               "recovered_frames": len(motion.metadata["recovered_frames"]),
               "unconverged_frames": len(motion.metadata["unconverged_frames"])}
        if method.startswith("domains"):
            d = motion.metadata["domains"]
            row.update(cubature=d["cubature"], loop_frames_per_s=d["frames_per_s"], dofs=d["dofs"],
                       forces_per_frame=d["force_calls"] / motion.n_frames)
            if reference is None:
                reference = motion
            # every node's displacement against the reference solve's, over the whole trial
            basis = reference.model.domain_model.basis
            diff = np.linalg.norm(((motion.q - reference.q) @ basis.T).reshape(motion.n_frames, -1, 3), axis=2)
            row["vs_reference_max_mm"] = 1e3 * float(diff.max())
            row["vs_reference_rms_mm"] = 1e3 * float(np.sqrt(np.mean(diff ** 2)))
        out["methods"][method] = row
        print(f"  [{name}] {method}: {row['frames_per_s']:.1f} frames/s", flush=True)
    if validate_too:
        from tonguevis.analysis import validate
        from tonguevis.analysis.validation_domains import held_out_domains

        nan = float("nan")

        domains = held_out_domains(rec, model)
        try:
            sensors = validate(rec, model, quasi_static=False).sensors
        except Exception as exc:  # noqa: BLE001 - the domains' figures are still worth printing
            print(f"  validate failed ({type(exc).__name__}: {exc}); the domains' held-out figures alone")
            sensors = {name: {} for name in domains}
        held = {}
        for sensor, scores in sensors.items():
            held[sensor] = {"warped": scores.get("model_rmse_mm", nan), "linear": scores.get("linear_rmse_mm", nan),
                            "kinematic": scores.get("kinematic_rmse_mm", nan),
                            "domains": domains.get(sensor, {}).get("rmse_mm", float("nan"))}
        out["held_out_rmse_mm"] = held
        out["held_out_mean_mm"] = {m: float(np.nanmean([h[m] for h in held.values()]))
                                   for m in ("warped", "linear", "kinematic", "domains")}
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, metavar="OUT", help="write the figures as JSON")
    parser.add_argument("--no-validate", action="store_true", help="speed and plausibility only")
    parser.add_argument("--demo-only", action="store_true", help="the demo recording only")
    parser.add_argument("--recording", type=int, action="append", metavar="I",
                        help="only recording I of the list (0 demo, 1 Opti-Speech 009, 2 Haskins); repeatable")
    parser.add_argument("--repeat", type=int, default=3, help="timed calls per method, the best kept (default 3)")
    args = parser.parse_args(argv)
    rows = []
    chosen = RECORDINGS[:1] if args.demo_only else RECORDINGS
    if args.recording:
        chosen = [RECORDINGS[i] for i in args.recording]
    for name, path in chosen:
        if not path.exists():
            print(f"{name}: {path} not present, skipped")
            continue
        row = run(name, path, not args.no_validate, args.repeat)
        rows.append(row)
        print(f"\n{name}: {row['frames']} frames at {row['rate_hz']:.0f} Hz, {os.cpu_count()} cores")
        print(f"  {'method':<19} {'frames/s':>9} {'ampl.':>6} {'vol %':>6} {'misfit rms/max mm':>18}")
        for method, r in row["methods"].items():
            extra = (f"  (frame loop {r['loop_frames_per_s']:.0f} frames/s, {r['forces_per_frame']:.2f} forces a frame, "
                     f"{r['dofs']} DOFs; vs reference max {r['vs_reference_max_mm']:.4f} mm, "
                     f"RMS {r['vs_reference_rms_mm']:.5f} mm)" if method.startswith("domains") else "")
            print(f"  {method:<19} {r['frames_per_s']:9.1f} {r['amplification']:6.2f} {r['volume_change_max_percent']:6.2f} "
                  f"{r['sensor_misfit_rms_mm']:8.2f} / {r['sensor_misfit_max_mm']:.2f}{extra}")
        if "held_out_rmse_mm" in row:
            print("  held-out RMSE, mm: " + "; ".join(
                f"{s}: " + ", ".join(f"{m} {v:.2f}" for m, v in h.items()) for s, h in row["held_out_rmse_mm"].items()))
            print("  mean: " + ", ".join(f"{m} {v:.2f}" for m, v in row["held_out_mean_mm"].items()))
    if args.json:
        from tonguevis._files import atomic_write_text

        atomic_write_text(args.json, json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
