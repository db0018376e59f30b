"""``tonguevis measures FILE``: what a paper reports per production, and how variable the repetitions are.

Reads the recording, removes head motion (three or more REF* sensors), takes its productions as
``tonguevis syllables`` does (a ``productions`` tier or ``--productions-from TIER`` wins; else
found: the 2nd-4th of each train of three or more, ``--all`` every one) and prints one row per
production: the constriction degree and location against the palate (``--palate``: the speaker's
from ``tonguevis palate``; default the generic one placed in the speaker), peak closing and opening
speeds, displacements, stiffness, lip aperture and protrusion, jaw opening, durations; then the
spatiotemporal index (STI, Smith et al. 2000) of every sensor over those productions.
``--out`` writes the table (CSV, or Parquet for ``.parquet``), ``--json`` the STI with the
productions' boundaries and the table, ``--averages`` the time-normalised mean ± SD trajectories,
``--png`` their figure.  The README's "Measures" says how each figure is defined.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from tonguevis.cli._common import add_productions_from_argument, add_recording_arguments

    add_recording_arguments(parser)
    parser.add_argument("--palate", default="generic", metavar="P",
                        help="the palate the constriction is measured against: a palate file from tonguevis palate "
                             "(the speaker's, registered by head references when both recordings have them), "
                             "'generic' (default: the shipped palate placed in the speaker by the rest sensors, an "
                             "estimate) or 'none'")
    parser.add_argument("--out", type=Path, metavar="TABLE", help="write the table: CSV, or Parquet for a .parquet name")
    parser.add_argument("--json", type=Path, metavar="OUT",
                        help='write {"sti": {SENSOR: ...}, "signal": ..., "n": ...}, the productions\' boundaries '
                             "and the table as JSON")
    parser.add_argument("--averages", type=Path, metavar="TABLE",
                        help="write the time-normalised mean ± SD trajectory of every sensor (1 %% steps): CSV, or "
                             "Parquet for a .parquet name")
    parser.add_argument("--png", type=Path, metavar="FIG", help="plot the mean ± SD trajectories with the STI")
    add_productions_from_argument(parser)
    parser.add_argument("--label", metavar="TEXT", help="only the productions labelled TEXT (e.g. one word)")
    parser.add_argument("--articulator", metavar="SENSOR",
                        help="the sensor whose closures make the productions (TT, TD, ...; LA: the lip aperture); "
                             "default: from --syllable, the file name, or the data")
    parser.add_argument("--syllable", metavar="CV", help="the syllable spoken (ta, ka, ...): chooses the articulator")
    parser.add_argument("--automatic", action="store_true",
                        help="find the productions even when a TextGrid beside the recording has a 'productions' tier")
    parser.add_argument("--all", action="store_true",
                        help="every production; default: the 2nd to 4th of each train of three or more")
    parser.add_argument("--no-head-correction", action="store_true",
                        help="use the positions as recorded even when head references exist")
    parser.add_argument("--rest", type=float, nargs=2, metavar=("START", "END"),
                        help="the rest interval (s) the jaw opening and lip protrusion are measured from; default: "
                             "the longest still interval of >= 1 s, else the stillest 0.2 s window (as every command)")


def run(args: argparse.Namespace) -> int:
    from tonguevis.analysis.measures import measures_text, write_measures
    from tonguevis.cli._common import read_recording_args, rest_arg
    from tonguevis.workflows.measures import measure_recording, write_averages, write_repetitions_json

    palate = args.palate
    if palate not in ("generic", "none"):
        from tonguevis.palate import load_palate

        palate = load_palate(Path(palate))  # read now: a bad file is said before anything else runs
        palate.metadata.setdefault("file", str(args.palate))
    rest = rest_arg(args)
    rec = read_recording_args(args)
    result = measure_recording(rec, palate, tier=args.productions_from, keep=None if args.all else (2, 3, 4),
                               articulator=args.articulator, syllable=args.syllable, labelled=not args.automatic,
                               head_correction=not args.no_head_correction, rest=rest, label=args.label)
    table, reps = result.table, result.repetitions
    print(f"file: {args.file}")
    print(f"palate: {result.palate.label or 'none (no constriction measured)'}")
    source = "labelled" if table.articulator_reason == "labelled" else f"found on {table.articulator}"
    print(f"productions: {len(table)} ({source}); positions head-corrected, mm; speeds of the 12 Hz low-passed sensor")
    if result.rest is not None:
        print(f"jaw and lips from {result.rest.describe()}")
    print(measures_text(result.rows))
    print(f"STI over the {reps.n} productions (vertical position, time- and amplitude-normalised; Smith et al. 2000): "
          + ", ".join(f"{name} {value:.2f}" if math.isfinite(value) else f"{name} -" for name, value in reps.sti.items()))
    for note in list(table.notes) + result.notes:
        print(f"note: {note}")
    if args.out is not None:
        write_measures(result.rows, args.out)
        print(f"wrote {args.out} ({len(result.rows)} productions)")
    if args.json is not None:
        write_repetitions_json(result, args.json, {"file": str(args.file), "palate": result.palate.label,
                                                   "measures": [_jsonable(row) for row in result.rows]})
        print(f"wrote {args.json}")
    if args.averages is not None:
        write_averages(result, args.averages)
        print(f"wrote {args.averages}")
    if args.png is not None:
        from tonguevis.render.repetitions import save_averages_png

        save_averages_png(reps, args.png, title=f"{args.file.name}: {reps.n} productions, mean ± SD")
        print(f"wrote {args.png}")
    return 0


def _jsonable(row: dict) -> dict:
    """A measures row for JSON: NaN as null."""
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()}
