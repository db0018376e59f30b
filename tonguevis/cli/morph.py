"""``tonguevis morph SOURCE@TIME TARGET@TIME --out MP4|PNG``: morph one simulated shape into another (§6.4).

SOURCE and TARGET are recordings (simulated here on one tongue model) or
motions saved by ``tonguevis simulate`` (``.npz``); TIME is in seconds on
each one's clock and picks the nearest frame.  The blend is
q(t) = (1 − t) q_source + t q_target: t = 0 is the SOURCE, t = 1 the TARGET.
Elements are coloured by the percentile (empirical CDF) of their
source–target difference, eq. (14): blue = alike, red = most different.
``--out x.png`` writes a strip of snapshots from source to target;
``--out x.mp4`` plays the morph forward and back with the three small views.
"""

from __future__ import annotations

import argparse
from pathlib import Path



def _frame_spec(text: str) -> tuple[Path, float]:
    path, sep, time = text.rpartition("@")
    if not sep or not path:
        raise argparse.ArgumentTypeError(f"{text!r}: expected FILE@TIME, e.g. data/spk1_la.tsv@6.1")
    try:
        return Path(path), float(time)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: the time after @ must be seconds, got {time!r}") from None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from tonguevis.cli._common import add_reader_options_argument, add_run_arguments

    parser.add_argument("source", type=_frame_spec, metavar="SOURCE@TIME", help="source shape (t = 0)")
    parser.add_argument("target", type=_frame_spec, metavar="TARGET@TIME", help="target shape (t = 1)")
    parser.add_argument("--out", type=Path, required=True, metavar="MP4|PNG", help="output video or image")
    parser.add_argument("--frames", type=int, default=60, help="MP4 frames from source to target (default 60)")
    parser.add_argument("--fps", type=int, default=30, help="MP4 frame rate (default 30)")
    parser.add_argument("--difference", choices=("eq14", "node_mean"), default="eq14",
                        help="element difference the colours rank: eq14 (the paper's, divided by the element volume) "
                             "or node_mean (mean squared node distance, independent of element size)")
    parser.add_argument("--one-way", action="store_true", help="MP4 plays source → target only (default: and back)")
    parser.add_argument("--sensors", metavar="MAP", help="sensor map for recordings (default: sensor_map.json beside)")
    add_reader_options_argument(parser, " of both recordings")
    add_run_arguments(parser, every=True)


def load_model(args):
    """The tongue model recordings are simulated on: ``mesh`` when given, else the shipped default."""
    from tonguevis.cli._common import load_model_args

    return load_model_args(args)


def _motion(path: Path, model, args, progress):
    from tonguevis.cli._common import reading_options, simulate_args
    from tonguevis.sim import Motion
    from tonguevis.workflows.recording import open_recording

    if path.suffix.lower() == ".npz":
        return Motion.load(path)
    # a sensor_map.json beside the file is used by default
    rec = open_recording(path, args.sensors, **reading_options(args))
    return simulate_args(args, rec, model, progress=progress)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from tonguevis._progress import tqdm_progress
    from tonguevis.analysis.morph import MorphError, morph_between
    from tonguevis.render.morph import render_mp4, render_png
    from tonguevis.cli._common import rest_line

    suffix = args.out.suffix.lower()
    if suffix not in (".mp4", ".png"):
        raise MorphError(f"--out must end in .mp4 or .png, got {args.out.name!r}")
    if args.frames < 2:
        raise MorphError(f"--frames must be at least 2, got {args.frames}")
    (src_path, src_time), (tgt_path, tgt_time) = args.source, args.target
    if args.rest is not None and all(p.suffix.lower() == ".npz" for p in (src_path, tgt_path)):
        raise MorphError("--rest needs a recording to simulate; saved motions keep the rest they were simulated "
                         "with", src_path)
    motions = {}
    model = None
    # A saved motion brings its own model; recordings are simulated on it (or on the default).
    for path in (src_path, tgt_path):
        if path.suffix.lower() == ".npz" and path not in motions:
            motions[path] = _motion(path, None, args, None)
            model = model or motions[path].model
    with tqdm_progress("simulating", disable=args.quiet) as progress:
        for path in (src_path, tgt_path):
            if path not in motions:
                model = model or load_model(args)
                motions[path] = _motion(path, model, args, progress)
    morph = morph_between(motions[src_path], src_time, motions[tgt_path], tgt_time, difference=args.difference)
    src, tgt = motions[src_path], motions[tgt_path]
    morph.labels = (f"{src_path.stem} @ {src.times[morph.source_frame]:.2f} s",
                    f"{tgt_path.stem} @ {tgt.times[morph.target_frame]:.2f} s")
    diff = morph.element_difference
    for path in dict.fromkeys((src_path, tgt_path)):
        print(f"{path.name}: {rest_line(motions[path])}")
    print(f"source (t = 0): {morph.labels[0]}, energy {1e3 * src.energy[morph.source_frame]:.3f} mJ")
    print(f"target (t = 1): {morph.labels[1]}, energy {1e3 * tgt.energy[morph.target_frame]:.3f} mJ")
    gap = 1e3 * np.linalg.norm(morph.source_displacement - morph.target_displacement, axis=1)
    print(f"node distance source-target: max {gap.max():.2f} mm, mean {gap.mean():.2f} mm; "
          f"element difference ({args.difference}) median {np.median(diff):.3g} {morph.difference_unit}, "
          f"max {diff.max():.3g} {morph.difference_unit}")
    title = "q(t) = (1-t) q_source + t q_target"
    if suffix == ".png":
        render_png(morph, args.out, title=title)
    else:
        with tqdm_progress("rendering", disable=args.quiet) as progress:
            render_mp4(morph, args.out, n_frames=args.frames, fps=args.fps, back=not args.one_way,
                       title=title, progress=progress)
    print(f"wrote {args.out}")
    return 0
