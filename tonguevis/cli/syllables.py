"""``tonguevis syllables FILE``: the CV productions of a recording and their gesture landmarks.

Reads the recording (any supported format), removes head motion when three or
more head references (REF1, REF2, ...) are present, chooses the consonant's
articulator (the syllable's place when it is named or in the file name, else the
data), finds its closures (within the sound's trains when there is sound) and prints
one row per production: train, position, label, articulator, start and end, release,
closure and vowel times in seconds, duration, and how clear it was.  A ``productions``
tier in a TextGrid beside the recording, or ``--productions-from TIER``, wins.
``--gestures OUT`` writes the gesture landmarks (CSV, or Parquet for ``.parquet``);
``--textgrid OUT`` writes the productions for Praat (interval tier ``productions``,
point tier ``events``, a point tier per landmark, beside the recording's own tiers).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tonguevis._logging import logger


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from tonguevis.cli._common import add_companion_arguments, add_productions_from_argument, add_reader_options_argument

    parser.add_argument("file", type=Path, help="the recording (NDI Wave TSV, Carstens .pos, EST .ema, ...)")
    parser.add_argument("--sensors", metavar="MAP",
                        help="sensor map: a JSON file or a preset (paper, haskins, mngu0) naming which "
                             "channel is TT, JAW, REF1...; default: sensor_map.json beside FILE if any")
    add_reader_options_argument(parser)
    add_companion_arguments(parser)
    parser.add_argument("--csv", metavar="OUT", type=Path, help="also write the table to this CSV file")
    parser.add_argument("--gestures", metavar="OUT", type=Path,
                        help="also write the gesture landmarks of every production (onset, peak velocity, nucleus "
                             "onset, maximum constriction, nucleus offset, second peak velocity, offset, vowel "
                             "target: times, positions, speeds, durations): CSV, or Parquet for a .parquet name")
    parser.add_argument("--textgrid", metavar="OUT", type=Path,
                        help="also write a Praat TextGrid: the productions as interval tier 'productions' "
                             "(text: the syllable, else train.index), releases and vowels as point tier 'events', "
                             "each gesture landmark as a point tier (GONS, PVEL, NONS, MAXC, NOFFS, PVEL2, GOFFS, "
                             "VTARG), with the recording's own tiers; saved as NAME.TextGrid beside the recording, "
                             "its productions are used by every command")
    add_productions_from_argument(parser)
    parser.add_argument("--articulator", metavar="SENSOR",
                        help="the sensor whose closures make the productions (TT, TD, ...; LA: the lip aperture "
                             "from UL and LL); default: from --syllable, the file name, or the data")
    parser.add_argument("--tip", dest="articulator", help=argparse.SUPPRESS)  # the old name, one release
    parser.add_argument("--syllable", metavar="CV",
                        help="the syllable spoken (ta, ka, pa...): its consonant's place chooses the articulator "
                             "and it labels every production")
    parser.add_argument("--automatic", action="store_true",
                        help="find the productions even when a TextGrid beside the recording has a "
                             "'productions' tier")
    parser.add_argument("--all", action="store_true",
                        help="every production; default: the 2nd to 4th of each train, as the paper")
    parser.add_argument("--no-head-correction", action="store_true",
                        help="use the positions as recorded even when head references exist")


def run(args: argparse.Namespace) -> int:
    from tonguevis.cli._common import reading_options
    from tonguevis.io.textgrid import tier_names
    from tonguevis.preprocess.labelled import PRODUCTIONS_TIER
    from tonguevis.workflows.recording import find_recording_productions, head_references, open_recording

    rec = open_recording(args.file, args.sensors, **reading_options(args))
    sensor_map = rec.metadata.get("sensor_map")
    tier = args.productions_from
    if tier is None and not args.automatic and PRODUCTIONS_TIER in tier_names(rec.labels):
        tier = PRODUCTIONS_TIER
    lines = [f"file: {args.file}"]
    if sensor_map is not None:
        lines.append(f"sensor map: {sensor_map}")
    references = head_references(rec)
    if references and not args.no_head_correction:
        lines.append(f"head motion removed with {', '.join(references)}")
    if rec.metadata.get("labels_file"):
        lines.append(f"labels: {rec.metadata['labels_file']}")
    table = find_recording_productions(rec, articulator=args.articulator, keep=None if args.all else (2, 3, 4),
                                       head_correction=not args.no_head_correction, tier=tier,
                                       syllable=args.syllable, labelled=False)
    if tier is not None:
        source = f"label tier {tier!r}: touching intervals form a train"
        shown = "every labelled interval"
    else:
        source = ("audio envelope" if rec.audio is not None and len(rec.audio.samples)
                  else f"{table.articulator} motion: closures under 1 s apart")
        shown = "all" if args.all else "2nd-4th of each train of three or more; isolated ones and pairs all"
        lines.append(f"articulator: {table.articulator} ({table.articulator_reason})")
    lines.append(f"trains: {len(table.trains)} (from the {source}); productions found per train: "
                 f"{', '.join(map(str, table.counts)) or 'none'}")
    lines.append(f"productions shown: {shown} ({len(table)}); times in seconds, "
                 + ("interval start to end" if tier is not None else "release to the next release or the vowel's end"))
    print("\n".join(lines))
    print(table.to_text())
    for note in table.notes:
        print(f"note: {note}")
    if not table.clear:
        logger.warning("%s: the syllables are unclear (see the notes): the productions above are a guess", args.file)
    if args.csv is not None:
        table.to_csv(args.csv)
        print(f"wrote {args.csv}")
    if args.gestures is not None:
        from tonguevis.preprocess.gesture_table import write_gestures

        write_gestures(table, args.gestures)
        print(f"wrote {args.gestures} (gesture landmarks of {len(table)} productions)")
    if args.textgrid is not None:
        from tonguevis.preprocess.labelled import write_productions_textgrid

        tiers = write_productions_textgrid(args.textgrid, table, rec)
        print(f"wrote {args.textgrid} (tiers: {', '.join(tiers)})")
    return 0
