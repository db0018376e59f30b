#!/usr/bin/env python
"""The gesture landmarks figure of the README: the demo /ka/ (SYNTHETIC) with its productions.

Top: the consonant's articulator (the dorsum, TD, for /k/) going up to each closure and down to
the vowel, every production shaded from its release, its landmarks marked (lp_findgest's gesture
onset and offset, peak velocities, nucleus onset and offset, maximum constriction, and the vowel
target).  Bottom: the tangential speed with each gesture's 20 % thresholds.  Made from
``data/spk1_ka.tsv`` as ``tonguevis syllables`` finds them; writes docs/images/landmarks.png.

    python scripts/make_landmarks_figure.py [--recording data/spk1_ka.tsv] [--start 5.0 --end 6.7]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=REPO / "data" / "spk1_ka.tsv")
    parser.add_argument("--start", type=float, default=5.0)
    parser.add_argument("--end", type=float, default=6.7)
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "images" / "landmarks.png")
    args = parser.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tonguevis._files import atomic_write
    from tonguevis.preprocess.articulators import constriction_signal
    from tonguevis.preprocess.gestures import VELOCITY_THRESHOLD
    from tonguevis.render.production_marks import mark_landmarks, shade_productions
    from tonguevis.workflows import find_recording_productions, head_corrected, open_recording

    rec = open_recording(args.recording)
    table = find_recording_productions(rec, keep=None)
    signal = constriction_signal(head_corrected(rec), table.articulator)
    t = rec.times
    shown = (t >= args.start) & (t <= args.end)
    inside = [k for k, p in enumerate(table) if args.start <= p.start <= args.end]
    productions = [table[k] for k in inside]
    landmarks = [table.landmarks[k] for k in inside]

    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(11, 5.2), height_ratios=[1.6, 1],
                                      layout="constrained")
    height = 1000 * signal.signal
    top.plot(t[shown], height[shown], color="#2980b9", lw=1.2, label=f"{table.articulator} height (mm)")
    shade_productions(top, [(p.start, p.end) for p in productions])
    mark_landmarks(top, landmarks, t, height, legend=True, size=7, above=True)
    for p in productions:
        top.annotate(p.name, (p.start, 0.98), xycoords=("data", "axes fraction"), fontsize=7, va="top",
                     ha="left", color="#555555", xytext=(2, 0), textcoords="offset points")
    top.set_ylabel(f"{table.articulator} z (mm,\nhead frame)", fontsize=9)
    speed = 1000 * signal.speed
    bottom.plot(t[shown], speed[shown], color="#34495e", lw=1.0)
    for m in landmarks:
        for peak_time, peak, first, last in ((m.times["pvel"], m.peak_velocity, "gons", "nons"),
                                             (m.times["pvel2"], m.peak_velocity2, "noffs", "goffs")):
            level = 1000 * VELOCITY_THRESHOLD * peak
            bottom.hlines(level, m.times[first], m.times[last], colors="#d35400", lw=0.8, linestyles=":")
    shade_productions(bottom, [(p.start, p.end) for p in productions])
    bottom.set_ylabel("tangential speed\n(mm/s)", fontsize=9)
    bottom.set_xlabel("time (s)", fontsize=9)
    bottom.set_xlim(args.start, args.end)
    for ax in (top, bottom):
        ax.tick_params(labelsize=8)
        ax.grid(True, lw=0.3, alpha=0.5)
    fig.suptitle(f"{args.recording.name} (SYNTHETIC demo), its first train: productions on {table.articulator} "
                 "shaded from each release; dotted: 20 % of each peak speed", fontsize=10, x=0.01, ha="left")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(args.out, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
