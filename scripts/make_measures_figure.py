#!/usr/bin/env python
"""The repetitions figure of the README: the demo's /ta/ and /ka/ (SYNTHETIC), mean ± SD per sensor, with the STI.

Speaker 1's /ta/ and /ka/ productions as ``tonguevis measures`` takes them (the 2nd-4th of each train
of five), each sensor's vertical position time-normalised from the production's start to its end,
the mean ± 1 SD band of each syllable, and each one's spatiotemporal index (Smith et al. 2000) in
the legend.  Made from the embedded demo only (``data/``); writes docs/images/measures_averages.png
and prints the measures the README quotes.

    python scripts/make_measures_figure.py [--data data] [--out docs/images/measures_averages.png]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SENSORS = ("TT", "TD", "TL", "TR", "JAW")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO / "data")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "images" / "measures_averages.png")
    args = parser.parse_args(argv)

    from tonguevis.render.repetitions import save_averages_png
    from tonguevis.workflows import open_recording
    from tonguevis.workflows.measures import measure_recording

    groups = {}
    for syllable in ("ta", "ka"):
        result = measure_recording(open_recording(args.data / f"spk1_{syllable}.tsv"), "generic")
        groups[f"/{syllable}/"] = result.repetitions
        rows = result.rows
        for key in ("constriction_degree_mm", "constriction_location_mm", "peak_velocity_closing_mm_s",
                    "displacement_closing_mm", "stiffness_closing_per_s", "jaw_opening_vowel_mm"):
            values = np.array([row[key] for row in rows], dtype=float)
            print(f"spk1 /{syllable}/ {key}: {np.nanmean(values):.2f} ± {np.nanstd(values, ddof=1):.2f} "
                  f"(n = {len(values)}, {rows[0]['articulator']})")
        print(f"spk1 /{syllable}/ STI: " + ", ".join(f"{k} {v:.2f}" for k, v in result.repetitions.sti.items()))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_averages_png(groups, args.out, sensors=SENSORS,
                      title="SYNTHETIC demo, speaker 1: /ta/ and /ka/ (2nd-4th of each train), vertical position, "
                            "mean ± 1 SD over normalised time")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
