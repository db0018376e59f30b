#!/usr/bin/env python
"""The picture a clinician sees, measured on the shared real recordings (issue 23), default settings.

Per recording (Opti-Speech /ta/ 009, /ka/ 006 and 007 with the speaker's palate fitted from the
session's three traces; the Haskins sentence without a palate): the model's fit in the speaker's
frame (size, volume), the plausibility figures of the motion the app shows (sensor misfit,
far-field amplification, volume change), contact (deepest penetration, frames in contact, largest
area, the frames where a sensor is within 1 mm of the palate and how many of them show the tongue
touching it), and the leave-one-sensor-out validation per held-out sensor beside the kinematic
baseline (the interpolation of the other sensors).

    python scripts/report_picture.py [--no-validate] [--tongue-size X|adult|alignment] [--no-sensor-patches] [--fit-rest]

Summary figures only: never commit per-sample output of the third-party recordings.
Measured 2026-12-03 (default settings: speaker frame, sensors on the surface, compliant springs):
see the issue 23 closing note and docs/validation.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data" / "ema"
OPTI = SHARED / "optispeech"
RECORDINGS = [
    ("/ta/ 009", OPTI / "009_OSN12_Tah_withFb_natural_HR.tsv", None, True),
    ("/ka/ 006", OPTI / "006_OSN12_Kah_nofb_natural_take2_HR.tsv", None, True),
    ("/ka/ 007", OPTI / "007_OSN12_Kah_withFb_natural_HR.tsv", None, True),
    ("Haskins", SHARED / "mview" / "F01_B01_S01_R01_N.mat", "haskins", False),
]


def main(argv=None) -> int:
    from tonguevis.cli._common import _tongue_size_arg  # the commands' own reading of X|adult|alignment

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-validate", action="store_true")
    parser.add_argument("--tongue-size", type=_tongue_size_arg, default="adult", help="X, adult (the default) or alignment")
    parser.add_argument("--no-sensor-patches", action="store_true")
    parser.add_argument("--fit-rest", action="store_true", help="the rest shape fitted to the rest sensors")
    args = parser.parse_args(argv)
    if not OPTI.exists():
        print(f"the shared recordings are not at {SHARED}: nothing to measure")
        return 0
    from tonguevis._logging import set_log_level
    from tonguevis.analysis.validation import validate
    from tonguevis.sim.simulate import TOUCH_REACH
    from tonguevis.workflows import open_recording
    from tonguevis.workflows.palate import palate_from_traces
    from tonguevis.sim.settings import RunSettings, build_model
    from tonguevis.workflows.simulation import simulate_recording

    set_log_level("ERROR")
    palate = palate_from_traces(sorted(OPTI.glob("00[234]_*.tsv")))
    patches = None if args.no_sensor_patches else "default"
    settings = RunSettings(sensor_patches=patches, tongue_size=args.tongue_size, rest_fit=args.fit_rest)
    model = build_model(settings)
    lost, runs = 0, 0
    for name, path, sensor_map, with_palate in RECORDINGS:
        if not path.exists():
            print(f"{name}: {path} absent, skipped")
            continue
        started = time.perf_counter()
        rec = open_recording(path, sensor_map)
        run = settings.replace(palate=palate if with_palate else None)
        motion = simulate_recording(rec, model, run)
        fit, p = motion.metadata["fit"], motion.metadata["plausibility"]
        print(f"## {name} ({time.perf_counter() - started:.1f} s)")
        print(f"fit: the model at {1 / fit['scale']:.2f} x its size ({fit['model_volume_cm3']:.0f} cm³), rest "
              f"residual {fit['residual_rms_mm']:.2f} mm RMS"
              + (f"; rest shape fitted: sensors were {fit['rest_fit']['sensors_before_rms_mm']:.2f} mm RMS off, "
                 f"nodes moved up to {fit['rest_fit']['moved_max_mm']:.1f} mm, tets kept "
                 f"{100 * fit['rest_fit']['tet_volume_ratio_min']:.0f}-{100 * fit['rest_fit']['tet_volume_ratio_max']:.0f} "
                 f"% of their volume" if fit.get("rest_fit") else ""))
        print(f"misfit max {p['sensor_misfit_max_mm']:.2f} mm, amplification {p['amplification']:.2f}, "
              f"volume change max {p['volume_change_max_percent']:.2f} %")
        if with_palate:
            c = motion.metadata["contact"]
            sensors = motion.targets + motion.jaw_offset[:, None]
            gap, _ = motion.palate.clearance(sensors.reshape(-1, 3))
            gap = gap.reshape(sensors.shape[:2])
            near = (np.nan_to_num(gap, nan=1.0) <= TOUCH_REACH).any(axis=1)
            area = np.asarray(motion.contact_area)
            closest = {n: float(1e3 * np.nanmin(gap[:, k])) for k, n in enumerate(motion.sensor_names)}
            print(f"contact: deepest {c['penetration_max_mm']:.2f} mm, {c['frames_in_contact']} frames, largest "
                  f"area {c['contact_area_max_mm2']:.0f} mm², palate raised {c['palate_raised_mm']:.1f} mm; "
                  f"{int(near.sum())} frames with a sensor within 1 mm of the palate, "
                  f"{int((area[near] > 0).sum())} of them touching; closest approach per sensor (mm, negative: "
                  f"above): " + ", ".join(f"{n} {v:.1f}" for n, v in closest.items()))
        if args.no_validate:
            continue
        result = validate(rec, model, sensor_patches=patches, tongue_size=args.tongue_size, rest_fit=args.fit_rest)
        cells = []
        for sensor, s in result.sensors.items():
            runs += 1
            worse = s["model_rmse_mm"] > s["kinematic_rmse_mm"]
            lost += worse
            cells.append(f"{sensor} {s['model_rmse_mm']:.2f} vs {s['kinematic_rmse_mm']:.2f}{' (loses)' if worse else ''}")
        print("held-out RMSE, model vs interpolation (mm): " + "; ".join(cells))
    if runs:
        print(f"\nper-sensor held-out runs losing to interpolation: {lost} of {runs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
