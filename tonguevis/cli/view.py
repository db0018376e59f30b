"""``tonguevis view``: the desktop app (the demo when no file is given)."""

from __future__ import annotations

from pathlib import Path

#: Surface colourings (tonguevis.appstate.COLOR_MODES, spelled out so the parser needs no import).
COLOR_CHOICES = ("displacement", "energy", "contact", "plain", "difference")
#: What each means, in the app's words (its Colour by menu says "contact: distance to palate").
COLOR_HELP = ("displacement: magnitude, energy: elastic energy density, contact: distance to palate, "
              "difference: distance to B (compared recording), plain")


def add_arguments(parser) -> None:
    from tonguevis.cli._common import add_companion_arguments, add_reader_options_argument, add_run_arguments

    parser.add_argument("file", nargs="?", type=Path, help="an EMA recording (default: the demo /ta/ train, spk1_ta)")
    parser.add_argument("--sensors", metavar="MAP",
                        help="sensor map: a preset (paper, haskins, mngu0) or a JSON file of name -> channel")
    parser.add_argument("--screenshot", type=Path, metavar="PNG",
                        help="open the window, show --frame, save the whole window as PNG and exit")
    parser.add_argument("--frame", type=int, metavar="N", help="frame shown for --screenshot, counted from 0 as the "
                        "transport, the captions and the exports count them (default: the middle)")
    parser.add_argument("--reference", choices=("head", "jaw"), default="head",
                        help="frame of reference of the views: head (default: tongue and jaw move with the jaw, "
                             "palate fixed) or jaw (the jaw's motion removed)")
    parser.add_argument("--color", choices=COLOR_CHOICES, help=f"surface colouring (default: displacement; {COLOR_HELP})")
    parser.add_argument("--compare", type=Path, metavar="B",
                        help="a second recording shown with the first: two speakers, two trials, before and after")
    parser.add_argument("--compare-layout", choices=("side", "ghost"), default="side",
                        help="side: B in its own view beside A's, the same camera (default); ghost: B translucent "
                             "inside A's views")
    parser.add_argument("--compare-time", choices=("production", "absolute"), default="production",
                        help="production: each production of B laid over the same production of A by normalised "
                             "time (default); absolute: the same time on both clocks")
    parser.add_argument("--compare-linear", action="store_true",
                        help="simulate B without modal warping (compare a recording with itself: --compare A)")
    parser.add_argument("--compare-sensors", metavar="MAP", help="sensor map of B (as --sensors)")
    add_run_arguments(parser, quiet=False)
    add_reader_options_argument(parser, " of FILE")
    add_companion_arguments(parser)


def run(args) -> int:
    from tonguevis.cli._common import parse_options, reading_options, run_settings_of

    settings = run_settings_of(args)  # a bad setting or palate file stops here, as one line naming it
    parse_options(args.option)  # a malformed -O stops here, before a window opens
    reading = {**({"sensor_map": args.sensors} if args.sensors else {}), **reading_options(args)}
    from tonguevis.gui.app import run_view  # Qt only loads here: `import tonguevis.cli.view` stays light

    return run_view(args.file, settings, reading=reading, screenshot=args.screenshot, frame=args.frame,
                    look={"reference": args.reference, "color": args.color}, compare=_compare_options(args))


def _compare_options(args) -> dict | None:
    if args.compare is None:
        return None
    return {"path": args.compare, "sensor_map": args.compare_sensors, "layout": args.compare_layout,
            "time_mode": args.compare_time, "warping": False if args.compare_linear else None}
