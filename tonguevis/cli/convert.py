"""``tonguevis convert IN OUT``: rewrite a recording as BVH, CSV or NDI Wave TSV (by OUT's extension)."""

from __future__ import annotations

import argparse

from tonguevis.cli._common import parse_options
from tonguevis.cli.info import add_reading_arguments, read_from_args


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", help="an EMA recording in any format tonguevis reads")
    parser.add_argument("output", help="the file to write: .bvh, .csv or .tsv (NDI Wave, + .wav when there is audio)")
    add_reading_arguments(parser)
    parser.add_argument("-W", "--write-option", action="append", metavar="KEY=VALUE",
                        help="writer option, e.g. layout=long or unit=m (CSV), unit=mm (BVH); repeatable")


def _ndi_ids(sensor_map):
    """The map's NDI Ids when all its channels are numbers (so a TSV round-trips), else None."""
    from tonguevis.io import load_sensor_map

    if sensor_map is None:
        return None
    mapping = load_sensor_map(sensor_map)
    try:
        return {name: int(channel) for name, channel in mapping.items()}
    except (TypeError, ValueError):
        return None


def run(args) -> int:
    from tonguevis.io import write_recording
    from tonguevis.io.registry import FORMATS

    rec = read_from_args(args, args.input)
    options = parse_options(args.write_option)
    if args.output.lower().endswith(".tsv") and "sensor_map" not in options:
        ids = _ndi_ids(args.sensors)
        if ids is not None:
            options["sensor_map"] = ids
    writer_names = [f.name for f in FORMATS.values() if f.write is not None]
    try:
        write_recording(rec, args.output, **options)
    except TypeError as exc:
        from tonguevis.errors import RecordingError

        raise RecordingError(f"bad writer option ({exc}); writers: {', '.join(writer_names)}", args.output) from None
    print(f"wrote {args.output}: {len(rec.sensors)} sensors, {rec.n_samples} samples"
          + (", audio" if rec.audio is not None and args.output.lower().endswith(".tsv") else ""))
    return 0
