"""``tonguevis view``: the desktop app (the demo when no file is given)."""

from __future__ import annotations

from pathlib import Path


def add_arguments(parser) -> None:
    from tonguevis.cli._common import add_companion_arguments, add_rest_argument

    parser.add_argument("file", nargs="?", type=Path, help="an EMA recording (default: the demo /ta/ train, spk1_ta)")
    parser.add_argument("--sensors", metavar="MAP",
                        help="sensor map: a preset (paper, haskins, mngu0) or a JSON file of name -> channel")
    parser.add_argument("--mesh", type=Path, metavar="PATH", help="tetrahedral tongue mesh (default: the shipped one)")
    parser.add_argument("--modes", type=int, default=100, metavar="M", help="vibration modes (default 100)")
    parser.add_argument("--screenshot", type=Path, metavar="PNG",
                        help="open the window, show --frame, save the whole window as PNG and exit")
    parser.add_argument("--frame", type=int, metavar="N", help="frame shown for --screenshot (default: the middle)")
    add_rest_argument(parser)
    add_companion_arguments(parser)


def run(args) -> int:
    from tonguevis.cli._common import rest_arg

    rest = rest_arg(args)
    from tonguevis.gui.app import run_view  # Qt only loads here: `import tonguevis.cli.view` stays light

    return run_view(args.file, args.sensors, args.mesh, args.modes, args.screenshot, args.frame, rest=rest,
                    audio=args.audio, labels=args.label_file)
