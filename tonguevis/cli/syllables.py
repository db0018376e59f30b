"""``tonguevis syllables FILE``: the CV productions of a recording (§3.2).

Reads the recording (any supported format), removes head motion when three or
more head references (REF1, REF2, ...) are present, finds the syllable trains
(from the audio when there is some, else from the tongue-tip motion) and
prints one row per production: train, position in the train, start and end
(release to release), consonant release and vowel times in seconds.
``--productions-from TIER`` takes them from a label tier instead;
``--textgrid OUT`` writes them for Praat (interval tier ``productions``,
point tier ``events`` with the releases and vowels, beside the recording's own tiers).
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

log = logging.getLogger("tonguevis")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from tonguevis.cli._common import add_companion_arguments, add_productions_from_argument

    parser.add_argument("file", type=Path, help="the recording (NDI Wave TSV, Carstens .pos, EST .ema, ...)")
    parser.add_argument("--sensors", metavar="MAP",
                        help="sensor map: a JSON file or a preset (paper, haskins, mngu0) naming which "
                             "channel is TT, JAW, REF1...; default: sensor_map.json beside FILE if any")
    add_companion_arguments(parser)
    parser.add_argument("--csv", metavar="OUT", type=Path, help="also write the table to this CSV file")
    parser.add_argument("--textgrid", metavar="OUT", type=Path,
                        help="also write a Praat TextGrid: the productions as interval tier 'productions' "
                             "(text train.index), releases and vowels as point tier 'events', with the "
                             "recording's own tiers")
    add_productions_from_argument(parser)
    parser.add_argument("--tip", default="TT", help="the tongue-tip sensor (default: TT)")
    parser.add_argument("--all", action="store_true",
                        help="every production; default: the 2nd to 4th of each train, as the paper")
    parser.add_argument("--no-head-correction", action="store_true",
                        help="use the positions as recorded even when head references exist")


def run(args: argparse.Namespace) -> int:
    from tonguevis.cli._common import companion_options
    from tonguevis.errors import RecordingError
    from tonguevis.workflows import find_recording_productions, head_references, open_recording

    rec = open_recording(args.file, args.sensors, **companion_options(args))
    sensor_map = rec.metadata.get("sensor_map")
    tier = args.productions_from
    if args.tip not in rec.sensors and tier is None:
        raise RecordingError(
            f"no tongue-tip sensor {args.tip!r} (sensors: {', '.join(rec.sensor_names)}); name the "
            "channels with --sensors MAP or pick another with --tip", args.file)
    lines = [f"file: {args.file}"]
    if sensor_map is not None:
        lines.append(f"sensor map: {sensor_map}")
    references = head_references(rec)
    if references and not args.no_head_correction:
        lines.append(f"head motion removed with {', '.join(references)}")
    if rec.metadata.get("labels_file"):
        lines.append(f"labels: {rec.metadata['labels_file']}")
    if tier is not None:
        source = f"label tier {tier!r}: touching intervals form a train"
        shown = "every non-empty interval"
    else:
        source = "audio envelope" if rec.audio is not None and len(rec.audio.samples) else "tongue-tip motion"
        shown = "all" if args.all else "2nd-4th of each train"
    table = find_recording_productions(rec, tip=args.tip, keep=None if args.all else (2, 3, 4),
                                       head_correction=not args.no_head_correction, tier=tier)
    trains = table.trains
    lines.append(f"trains: {len(trains)} (from the {source}); productions found per train: "
                 f"{', '.join(map(str, table.counts)) or 'none'}")
    lines.append(f"productions shown: {shown} ({len(table)}); "
                 + ("times in seconds, interval start to end" if tier is not None
                    else "times in seconds, release to release"))
    print("\n".join(lines))
    print(table.to_text())
    for note in table.notes:
        print(f"note: {note}")
    if args.csv is not None:
        table.to_csv(args.csv)
        print(f"wrote {args.csv}")
    if args.textgrid is not None:
        from tonguevis.preprocess.labelled import write_productions_textgrid

        tiers = write_productions_textgrid(args.textgrid, table, rec)
        print(f"wrote {args.textgrid} (tiers: {', '.join(tiers)})")
    return 0
