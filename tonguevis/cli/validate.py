"""``tonguevis validate FILE --json OUT``: leave-one-sensor-out validation of the model.

For each tongue sensor in turn, the model is driven by the other tongue
sensors and the held-out sensor's node is compared with its measurement:
RMSE (mm, the speaker's by default, the model's with --model-frame) and mean per-axis correlation for the warped model,
the linear modal model, a quasi-static solve and a kinematic (RBF)
interpolation.  Writes the JSON document (and optionally a Markdown report)
and prints the table.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tonguevis.cli._common import (
    add_recording_arguments, add_run_arguments, load_model_args, read_recording_args, run_settings_of,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_recording_arguments(parser)
    add_run_arguments(parser)
    parser.add_argument("--no-static", action="store_true", help="skip the quasi-static baseline")
    parser.add_argument("--json", type=Path, required=True, metavar="OUT", help="write the results here (JSON)")
    parser.add_argument("--md", type=Path, metavar="OUT", help="also write a Markdown report")


#: Beyond this many seconds of recording the quasi-static baseline (a Newton solve per frame in
#: Python, per left-out sensor) takes longer than the rest of the validation many times over.
LONG_FOR_STATIC_S = 120.0


def long_static_advice(recording, no_static: bool) -> str | None:
    """A warning for a long recording validated with the quasi-static baseline, else None."""
    duration = float(recording.times[-1] - recording.times[0]) if recording.n_samples > 1 else 0.0
    if no_static or duration <= LONG_FOR_STATIC_S:
        return None
    return (f"{recording.metadata.get('file', 'the recording')}: {duration / 60:.0f} minutes; the quasi-static "
            "baseline solves every frame of every leave-one-out run in Python (for 30 minutes: over 20 minutes); "
            "--no-static skips it and keeps the model, linear and kinematic scores")


def run(args: argparse.Namespace) -> int:
    from tonguevis._progress import tqdm_progress
    from tonguevis.analysis.validation import validate
    from tonguevis._files import atomic_write_text
    from tonguevis.analysis.validation_report import axis_table, recording_markdown
    from tonguevis.preprocess.rest import RestChoice
    from tonguevis.sim.plausibility import plausibility_line

    settings = run_settings_of(args)  # first: a bad setting or palate is said before anything is read
    recording = read_recording_args(args)
    advice = long_static_advice(recording, args.no_static)
    if advice:
        from tonguevis._logging import logger

        logger.warning(advice)
    model = load_model_args(args)
    with tqdm_progress("validating", disable=args.quiet) as progress:
        result = validate(recording, settings, model, quasi_static=not args.no_static, progress=progress)
    print(plausibility_line(result.recording))
    doc = result.as_dict()
    result.write_json(args.json)
    text = recording_markdown(doc, title=str(args.file))
    if args.md is not None:
        atomic_write_text(args.md, text + "\nPer axis (x anterior, y left, z up):\n\n" + axis_table(doc) + "\n")
    r = doc["recording"]
    print(RestChoice(r["rest_interval_s"], r["rest_interval_from"], r.get("rest_interval_reason", "")).describe())
    print(text)
    print(f"wrote {args.json}" + (f" and {args.md}" if args.md else ""))
    return 0
