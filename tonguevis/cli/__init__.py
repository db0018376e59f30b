"""The ``tonguevis`` command.

Each subcommand lives in its own module ``tonguevis.cli.<name>`` defining
``add_arguments(parser)`` and ``run(args) -> int``; modules are imported only
when their command runs so that ``tonguevis info`` starts fast.  Errors the
user can cause (:class:`tonguevis.errors.TonguevisError`, ``OSError``) are
printed as one line on stderr with exit status 2, never as a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

# (command, module, one-line help).  Order is the order of ``tonguevis --help``.
COMMANDS: list[tuple[str, str, str]] = [
    ("view", "view", "open the desktop app on a recording (default: the demo)"),
    ("info", "info", "describe a recording: format, rate, sensors, audio, labels"),
    ("formats", "formats", "the recording formats tonguevis reads and everything it writes"),
    ("syllables", "syllables", "find the CV productions of a recording"),
    ("measures", "measures", "constriction, speed, stiffness per production and the repetitions' STI"),
    ("convert", "convert", "convert a recording to another format (BVH, CSV, NDI Wave TSV)"),
    ("export-wav", "export_wav", "the sound and every sensor's x, y, z as one multichannel WAV for Praat"),
    ("simulate", "simulate", "drive the tongue model with a recording"),
    ("export-video", "export_video", "render a recording's simulation to MP4 with its sound (if it has any)"),
    ("energy", "energy", "energy-time curves of the productions of recordings"),
    ("morph", "morph", "morph one simulated shape into another"),
    ("segment", "segment", "deformation segmentation with rigid or constraint modes"),
    ("validate", "validate", "leave-one-sensor-out validation of the model"),
    ("palate", "palate", "the speaker's palate surface from palate-trace recordings"),
    ("batch", "batch", "a whole corpus: simulate, energy, segment, validate; resumable, in parallel"),
    ("stream", "stream", "serve a recording over the NDI WaveFront real-time protocol (a replay server)"),
    ("record", "record", "record a live stream (NDI WaveFront) as an NDI Wave TSV, written as it arrives"),
    ("live", "live", "the live view: the tongue simulated from an articulograph's stream, targets, sweeps"),
]


def _module(name: str):
    return importlib.import_module(f"tonguevis.cli.{name}")


def build_parser(available_only: bool = True) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tonguevis",
        description="Physics-based deformable tongue visualisation from EMA recordings.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="say what happens (the log at level info)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for command, module_name, help_text in COMMANDS:
        try:
            module = _module(module_name)
        except ModuleNotFoundError as exc:
            if available_only and exc.name == f"tonguevis.cli.{module_name}":
                continue
            raise
        p = sub.add_parser(command, help=help_text, description=help_text)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    from tonguevis.errors import Cancelled, TonguevisError

    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:  # `tonguevis` or `tonguevis -v` alone: the app on the demo
        args = parser.parse_args([*argv, "view"])
    from tonguevis._logging import forget_warnings, set_log_level

    forget_warnings()  # each command says its warnings, once (tonguevis._logging.warn_once)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="tonguevis: %(levelname)s: %(message)s")
    set_log_level(args.verbose)
    if getattr(args, "_run", None) is None:
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except (TonguevisError, OSError) as exc:
        print(f"tonguevis {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except Cancelled:
        print(f"tonguevis {args.command}: cancelled", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print(f"tonguevis {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
