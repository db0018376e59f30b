"""``tonguevis info FILE``: what a recording holds (format, rate, sensors, audio, labels)."""

from __future__ import annotations

import argparse

import numpy as np


def add_reading_arguments(parser: argparse.ArgumentParser) -> None:
    from tonguevis.cli._common import add_companion_arguments, add_reader_options_argument

    parser.add_argument("--sensors", metavar="MAP",
                        help="sensor map: a preset (paper, haskins, mngu0) or a JSON file of name -> channel")
    parser.add_argument("--format", metavar="NAME", help="read as this format instead of detecting it")
    add_reader_options_argument(parser)
    add_companion_arguments(parser)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="an EMA recording (NDI Wave TSV, Carstens .pos, EST .ema, MVIEW .mat, BVH, CSV)")
    add_reading_arguments(parser)


def _gaps(dropped) -> str:
    if not dropped:
        return "none"
    missing = sum(n for _, n in dropped)
    shown = ", ".join(f"{n} after {t:.3f} s" for t, n in dropped[:5])
    more = f", ... ({len(dropped) - 5} more gaps)" if len(dropped) > 5 else ""
    return f"{missing} frame(s) missing in {len(dropped)} gap(s): {shown}{more}"


def _resampling(resampled) -> list[str]:
    """The ``resampled:`` line of a recording put on a uniform clock by its reader (Opti-Speech), else none."""
    if not isinstance(resampled, dict):
        return []
    merged = resampled.get("repeated_time_rows_merged", 0)
    rows = f"{resampled.get('rows', '?')} rows"
    if merged:
        rows += f" ({merged} repeating the previous row's timestamp, merged into it)"
    return [f"resampled:      {rows}, {resampled.get('distinct_samples', '?')} distinct samples, onto "
            f"{resampled.get('rate_hz', 0):g} Hz ({resampled.get('method', '?')})"]


def _rest_line(rec) -> str:
    """``rest:`` and the interval every command would take as the rest, and how it was found (the
    warning a simulation gives when there is no still second, said here as a line of the description)."""
    from tonguevis._logging import use_log_level
    from tonguevis.errors import TonguevisError
    from tonguevis.preprocess.rest import choose_rest_interval

    try:
        with use_log_level("error"):
            choice = choose_rest_interval(rec)
    except TonguevisError as exc:
        return f"rest:           not found: {exc}"
    return f"rest:           {choice.describe().removeprefix('rest: ')}"


def describe(rec) -> list[str]:
    """The lines ``tonguevis info`` prints for a recording."""
    from tonguevis.io.recording import unstated_axes_note
    from tonguevis.io.registry import FORMATS

    meta = rec.metadata
    fmt = meta.get("format", "?")
    lines = [
        f"file:           {meta.get('file', '?')}",
        f"format:         {fmt}" + (f" ({FORMATS[fmt].description})" if fmt in FORMATS else ""),
        f"sample rate:    {rec.rate:.3f} Hz",
        f"samples:        {rec.n_samples} ({rec.duration:.3f} s"
        + (f", {rec.times[0]:.3f} to {rec.times[-1]:.3f} s)" if rec.n_samples else ")"),
        f"length unit:    {meta.get('original_unit', '?')} in the file (metres inside tonguevis)",
        f"frame:          {meta.get('frame', '?')}" + (f" ({note})" if (note := unstated_axes_note(rec)) else ""),
        f"dropped frames: {_gaps(meta.get('dropped_frames', []))}",
        *_resampling(meta.get("resampled")),
        f"sensors ({len(rec.sensors)}):    name, valid samples, mean position x, y, z in mm",
    ]
    width = max((len(n) for n in rec.sensors), default=4)
    for name, xyz in rec.sensors.items():
        valid = rec.valid(name)
        if valid.any():
            mean = np.mean(xyz[valid], axis=0) * 1000.0
            where = "  ".join(f"{v:8.1f}" for v in mean)
        else:
            where = "no valid sample"
        quats = rec.orientations.get(name)  # the Q columns of an NDI Wave export may all be empty
        extra = " +orientation" if quats is not None and np.isfinite(quats).any() else ""
        lines.append(f"  {name:<{width}}  {100 * rec.valid_fraction(name):5.1f}%  {where}{extra}")
    lines.append(_rest_line(rec))
    if rec.audio is None:
        lines.append("audio:          none")
    else:
        source = meta.get("audio_file") or ("in the file" if meta.get("audio_source") == "embedded" else None)
        lines.append(f"audio:          {rec.audio.rate:.0f} Hz, {rec.audio.duration:.3f} s"
                     + (f" ({source})" if source else ""))
    if rec.labels:
        tiers: dict[str, int] = {}
        for label in rec.labels:
            tiers[label.tier] = tiers.get(label.tier, 0) + 1
        counts = ", ".join(f"{n} {tier}" for tier, n in tiers.items())
        words = [lab.text for lab in rec.labels if lab.tier == rec.labels[0].tier]
        text = " ".join(words[:12]) + (" ..." if len(words) > 12 else "")
        lines.append(f"labels:         {counts}: {text}")
        if meta.get("labels_file"):
            lines.append(f"label file:     {meta['labels_file']}")
    else:
        lines.append("labels:         none")
    if meta.get("sentence"):
        lines.append(f"sentence:       {meta['sentence']}")
    if meta.get("synthetic"):
        lines.append("note:           synthetic data")
    return lines


def read_from_args(args, path):
    from tonguevis.workflows.recording import open_recording

    from tonguevis.cli._common import reading_options

    return open_recording(path, args.sensors, format=args.format, **reading_options(args))


def run(args) -> int:
    rec = read_from_args(args, args.file)
    print("\n".join(describe(rec)))
    return 0
