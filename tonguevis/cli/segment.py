"""``tonguevis segment FILE``: deformation segmentation of a simulated recording (§5).

Simulates the recording on the tongue model, takes a target (the frame at
``--time``, a production with ``--production K``, by default the frame of peak
elastic energy), segments it with rigid or constraint modes from automatic
seeds (to ``--threshold`` or to ``--seeds N`` partitions) or from given seed
tets, and writes a VTU (partition and element error per cell; target and
approximation per node), optionally a PNG and the full result as ``.npz``.
"""

from __future__ import annotations

import argparse
from pathlib import Path


MODE_KINDS = ("rigid", "constraint")
DEFAULT_MODES = 100


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from tonguevis.cli._common import (DeprecatedAlias, add_companion_arguments, add_productions_from_argument,
                                       add_reader_options_argument, add_run_arguments)

    parser.add_argument("file", type=Path,
                        help="the recording (NDI Wave TSV, Carstens .pos, EST .ema, ...) or a saved motion (.npz)")
    parser.add_argument("--sensors", metavar="MAP",
                        help="sensor map: a preset (paper, haskins, mngu0) or a JSON file of name -> channel "
                             "(default: sensor_map.json beside the file, if there is one)")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--production", metavar="K", type=int,
                       help="segment production K (1-based, as listed by 'tonguevis syllables', with the same "
                            "--productions-from)")
    which.add_argument("--time", metavar="T", type=float, help="segment the frame nearest T seconds")
    add_productions_from_argument(parser)
    add_reader_options_argument(parser)
    add_companion_arguments(parser)
    parser.add_argument("--peak", action="store_true",
                        help="with --production: only its frame of peak energy (default: the whole "
                             "production, frames weighted by energy, eq. 5)")
    parser.add_argument("--mode-kind", choices=MODE_KINDS, default=None,
                        help="local modes: rigid (eq. 9) or constraint (eq. 13; default)")
    parser.add_argument("--seeds", default="auto", metavar="auto|N",
                        help="auto: add partitions until --threshold; N: autoseed exactly N partitions")
    parser.add_argument("--seed-tets", metavar="T1,T2,...",
                        help="seed tets (0-based) for Algorithm 5.1 instead of autoseeding")
    parser.add_argument("--threshold", type=float, default=0.05,
                        help="autoseeding stops when |u~ - u|^2 <= THRESHOLD |u|^2 (default 0.05)")
    parser.add_argument("--adjust", action="store_true",
                        help="post-segmentation adjustment: move interface tets while the error falls")
    parser.add_argument("--no-anchors", action="store_true",
                        help="constraint modes without the anchors as constrained nodes")
    parser.add_argument("--modal-modes", type=int, action=DeprecatedAlias, new="--modes")
    add_run_arguments(parser, modes_type=_count_or_old_kind, quiet=False)  # simulate's and the batch's: one motion
    parser.add_argument("--out", type=Path, required=True, metavar="OUT.vtu", help="VTU file to write")
    parser.add_argument("--png", type=Path, metavar="OUT.png", help="also render a picture (off screen)")
    parser.add_argument("--save", type=Path, metavar="OUT.npz", help="also save the whole result")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def _count_or_old_kind(text: str):
    """``--modes``: a count; 'rigid'/'constraint' (its meaning before ``--mode-kind``) for one more release."""
    if text in MODE_KINDS:
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of vibration modes (the kind of local modes "
                                         "is --mode-kind rigid|constraint)") from None


def resolve_mode_options(args) -> None:
    """``args.mode_kind`` and ``args.modes`` (a count) from the new names and the old ones
    (``--modes rigid|constraint``, ``--modal-modes M``), with a note for each old one."""
    from tonguevis.cli._common import deprecation_note

    old_kind = args.modes if isinstance(args.modes, str) else None
    if old_kind is not None:
        deprecation_note(f"--modes {old_kind}", f"--mode-kind {old_kind} (--modes is now the number of modes)")
        args.modes = None
    args.mode_kind = args.mode_kind or old_kind or "constraint"
    if args.modal_modes is not None:
        args.modes = args.modal_modes
    elif args.modes is None:
        args.modes = DEFAULT_MODES


def _seeding(args) -> dict:
    from tonguevis.analysis.segmentation import SegmentationError

    if args.seed_tets:
        try:
            tets = [int(t) for t in args.seed_tets.split(",") if t.strip()]
        except ValueError as exc:
            raise SegmentationError(f"--seed-tets wants comma-separated tet numbers, got {args.seed_tets!r}") from exc
        return {"seeds": tets}
    if args.seeds == "auto":
        return {"seeds": "auto", "threshold": args.threshold}
    try:
        count = int(args.seeds)
    except ValueError as exc:
        raise SegmentationError(f"--seeds wants 'auto' or a partition count, got {args.seeds!r}") from exc
    return {"seeds": "auto", "n_partitions": count, "threshold": None}


def _target(args, rec, motion):
    from tonguevis.analysis.segmentation import (
        SegmentationError,
        frame_target,
        peak_energy_target,
        production_target,
    )

    if args.time is not None:
        return frame_target(motion, time=args.time)
    if args.production is None:
        return peak_energy_target(motion)
    from tonguevis.workflows import find_recording_productions

    if rec is None:
        raise SegmentationError("--production needs the recording to find the productions: give the "
                                "recording itself, or keep it where the saved motion says it was", args.file)

    tier = getattr(args, "productions_from", None)
    table = find_recording_productions(rec, tier=tier)
    if not 1 <= args.production <= len(table):
        see = f"tonguevis syllables --productions-from {tier}" if tier is not None else "tonguevis syllables"
        raise SegmentationError(f"production {args.production} asked, the recording has {len(table)} "
                                f"(see '{see}')", args.file)
    production = table[args.production - 1]
    return peak_energy_target(motion, production) if args.peak else production_target(motion, production)


def load_model(mesh: Path | None, axes: str | None):
    """The tongue model: ours, or one built on ``--mesh`` with ``--mesh-axes`` (a hook the tests replace)."""
    from types import SimpleNamespace

    from tonguevis.cli._common import load_model_args

    return load_model_args(SimpleNamespace(mesh=mesh, mesh_axes=axes))


def _recording(path: Path, sensors, options=None):
    from tonguevis.workflows.recording import open_recording

    # a sensor_map.json, NAME.wav and NAME.TextGrid beside the file are used by default
    return open_recording(path, sensors, **(options or {}))


def _motion(args):
    """(recording or None, motion): a saved motion is loaded, a recording simulated."""
    from tonguevis.cli._common import reading_options, simulate_args
    from tonguevis.sim.motion import Motion

    if args.file.suffix.lower() == ".npz":
        motion = Motion.load(args.file)
        if args.rest is not None:
            from tonguevis.analysis.segmentation import SegmentationError
            from tonguevis.cli._common import rest_line

            raise SegmentationError(f"--rest needs a recording to simulate; this saved motion keeps its own "
                                    f"({rest_line(motion)})", args.file)
        source = motion.metadata.get("recording", {})
        source = source.get("file") if isinstance(source, dict) else source
        rec = None
        if args.production is not None and source and Path(source).exists():
            rec = _recording(Path(source), args.sensors, reading_options(args))
        return rec, motion
    rec = _recording(args.file, args.sensors, reading_options(args))
    model = load_model(args.mesh, args.mesh_axes)
    return rec, simulate_args(args, rec, model)


def run(args: argparse.Namespace) -> int:
    from tonguevis._progress import tqdm_progress
    from tonguevis.analysis.segmentation import segment
    from tonguevis.cli._common import rest_line

    resolve_mode_options(args)
    seeding = _seeding(args)
    if args.productions_from is not None and args.production is None:
        from tonguevis.analysis.segmentation import SegmentationError

        raise SegmentationError(f"--productions-from {args.productions_from} says where --production K is "
                                "counted; give --production K too", args.file)
    rec, motion = _motion(args)
    model = motion.model
    target = _target(args, rec, motion)
    with tqdm_progress(f"segmenting ({args.mode_kind} modes)", disable=args.quiet) as progress:
        result = segment(model, target, args.mode_kind, constrained_nodes=[] if args.no_anchors else None,
                         adjust=args.adjust, progress=progress, **seeding)
    result.metadata["recording"] = str(args.file)
    result.to_vtu(args.out)
    lines = [rest_line(motion), f"target: {target.description}",
             f"{result.n_partitions} partitions with {args.mode_kind} modes in {result.metadata['seconds']:.2f} s; "
             f"relative global error {100 * result.relative_error:.2f} % (|u~ - u|^2 / |u|^2)",
             "partition  tets  volume_cm3  rms_error_mm  seed_tet"]
    for row in result.partition_rows():
        lines.append(f"{row['partition']:9d} {row['tets']:5d} {row['volume_cm3']:11.2f} "
                     f"{row['rms_error_mm']:13.3f} {row['seed']:9d}")
    lines.append(f"wrote {args.out}")
    if args.save is not None:
        result.save(args.save)
        lines.append(f"wrote {args.save}")
    if args.png is not None:
        from tonguevis.render.segmentation import render_png

        render_png(result, args.png, titles=[f"{args.file.name}: {target.description}"])
        lines.append(f"wrote {args.png}")
    print("\n".join(lines))
    return 0
