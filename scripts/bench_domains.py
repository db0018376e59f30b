#!/usr/bin/env python
"""Seed 001's domains method (tonguevis.sim.domains) beside the modal methods, on whole recordings.

Per recording (the demo /ta/ and the shared real ones that are present: Opti-Speech /ta/ 009 and
the Haskins sentence), each method simulated over the whole trial, default settings:
frames/s of the whole ``simulate`` call (and, for the domains, of its frame loop alone), the
plausibility figures (far-field amplification, largest volume change, sensor misfit), and,
unless --no-validate, the held-out RMSE per tongue sensor: warped and linear from
:func:`tonguevis.analysis.validate`, the domains from :func:`tonguevis.analysis.validation_domains.held_out_domains`
(validate takes no method; the domains are seeded at the driving sensors only).

    python scripts/bench_domains.py [--json OUT] [--no-validate] [--demo-only]

Measured 2026-12-03 (2 shared cores, default settings; whole-call frames/s, frame loop in brackets):
demo /ta/ 1,762 frames: warped 1,857, linear 4,375, domains 21 (24), domains+cubature 151 (409);
Opti-Speech /ta/ 009, 1,093 frames: warped 4,209, linear 5,365, domains 31 (37), +cubature 93 (284);
Haskins sentence, 262 frames: warped 2,083, linear 2,931, domains 15 (17), +cubature 87 (442).
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


def run(name: str, path: Path, validate_too: bool) -> dict:
    import numpy as np

    from tonguevis.sim import TongueModel
    from tonguevis.sim.simulate import simulate
    from tonguevis.workflows.recording import open_recording

    rec = open_recording(path)
    model = TongueModel.default()
    out = {"recording": name, "frames": int(rec.on_uniform_grid().n_samples), "rate_hz": float(rec.rate),
           "methods": {}}
    from tonguevis.sim.domains import simulate_domains

    for method in METHODS + ("domains+cubature",):
        run_it = (lambda: simulate_domains(rec, model, cubature=True)) if method == "domains+cubature" else (
            lambda: simulate(rec, model, method=method))
        if method.startswith("domains"):  # the weights' (and cubature's) solve once: the figure is the simulation's
            run_it()
        t0 = time.perf_counter()
        motion = run_it()
        elapsed = time.perf_counter() - t0
        p = motion.metadata["plausibility"]
        row = {"frames_per_s": motion.n_frames / elapsed, "seconds": elapsed,
               "amplification": p["amplification"], "volume_change_max_percent": p["volume_change_max_percent"],
               "sensor_misfit_rms_mm": p["sensor_misfit_rms_mm"], "sensor_misfit_max_mm": p["sensor_misfit_max_mm"],
               "recovered_frames": len(motion.metadata["recovered_frames"]),
               "unconverged_frames": len(motion.metadata["unconverged_frames"])}
        if method.startswith("domains"):
            row["cubature"] = motion.metadata["domains"]["cubature"]
            row["loop_frames_per_s"] = motion.metadata["domains"]["frames_per_s"]
            row["dofs"] = motion.metadata["domains"]["dofs"]
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
    args = parser.parse_args(argv)
    rows = []
    for name, path in RECORDINGS[:1] if args.demo_only else RECORDINGS:
        if not path.exists():
            print(f"{name}: {path} not present, skipped")
            continue
        row = run(name, path, not args.no_validate)
        rows.append(row)
        print(f"\n{name}: {row['frames']} frames at {row['rate_hz']:.0f} Hz, {os.cpu_count()} cores")
        print(f"  {'method':<16} {'frames/s':>9} {'ampl.':>6} {'vol %':>6} {'misfit rms/max mm':>18}")
        for method, r in row["methods"].items():
            extra = (f"  (frame loop {r['loop_frames_per_s']:.0f} frames/s, {r['dofs']} DOFs)"
                     if method.startswith("domains") else "")
            print(f"  {method:<16} {r['frames_per_s']:9.1f} {r['amplification']:6.2f} {r['volume_change_max_percent']:6.2f} "
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
