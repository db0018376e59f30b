"""Arguments and steps that several commands share: reading a recording, the model, the rest, simulating.

The steps themselves live in :mod:`tonguevis.workflows`; this module only maps
command-line arguments onto them.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


class DeprecatedAlias(argparse.Action):
    """An option's old name, kept for one release: it works as before and prints a deprecation note.

    ``new`` is the option to use instead (shown in the note); the old name is
    left out of ``--help``.
    """

    def __init__(self, option_strings, dest, new: str, **kwargs):
        self.new = new
        kwargs.setdefault("help", argparse.SUPPRESS)
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        deprecation_note(option_string, self.new)
        setattr(namespace, self.dest, values)


def deprecation_note(old: str, new: str) -> None:
    """Print on stderr that option ``old`` is deprecated in favour of ``new`` (one line)."""
    print(f"tonguevis: note: {old} is deprecated and goes in the next release; use {new}", file=sys.stderr)


def add_recording_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, help="an EMA recording (NDI Wave TSV, Carstens .pos, EST .ema, MVIEW .mat, BVH, CSV)")
    parser.add_argument("--sensors", metavar="MAP",
                        help="sensor map: a preset (paper, haskins, mngu0) or a JSON file of name -> channel "
                             "(default: sensor_map.json beside the file, if there is one)")
    add_reader_options_argument(parser)
    add_companion_arguments(parser)


def add_reader_options_argument(parser: argparse.ArgumentParser, which: str = "") -> None:
    """``-O KEY=VALUE`` (repeatable): options of the reader of every recording the command reads."""
    parser.add_argument("-O", "--option", action="append", metavar="KEY=VALUE",
                        help=f"reader option{which}, e.g. channels=12 (headerless AG500), axes=-y,x,z (the "
                             "recording's axes), unit=mm, audio=false (no sound at all), labels=false; repeatable")


def parse_options(pairs: list[str] | None) -> dict:
    """``["channels=12", "axes=-y,x,z"]`` -> {"channels": 12, "axes": "-y,x,z"} (ints, floats, booleans)."""
    from tonguevis.errors import TonguevisError

    options = {}
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise TonguevisError(f"option {pair!r} is not KEY=VALUE")
        text = value.strip()
        parsed: object = text
        if text.lower() in ("true", "false"):
            parsed = text.lower() == "true"
        else:
            for convert in (int, float):
                try:
                    parsed = convert(text)
                    break
                except ValueError:
                    pass
        options[key.strip().replace("-", "_")] = parsed
    return options


def reading_options(args) -> dict:
    """Keyword arguments of :func:`tonguevis.workflows.open_recording` from ``-O`` then ``--audio``/``--labels``
    (the files given win over ``-O audio=...``)."""
    return {**parse_options(getattr(args, "option", None)), **companion_options(args)}


def add_companion_arguments(parser: argparse.ArgumentParser, labels: bool = True) -> None:
    """``--audio FILE`` and (unless ``labels=False``) ``--labels FILE``: the recording's sound and TextGrid."""
    parser.add_argument("--audio", type=Path, metavar="FILE",
                        help="the recording's sound (WAV); default: the file's own (MVIEW), else a WAV with the "
                             "same name beside it, or NAME.wav in a wav/ folder beside the pos/ folder (Carstens)")
    if labels:
        parser.add_argument("--labels", dest="label_file", type=Path, metavar="FILE",
                            help="Praat TextGrid of the recording's labels (its tiers join MVIEW's words and "
                                 "phones); default: NAME.TextGrid beside the recording")


def companion_options(args) -> dict:
    """``audio=`` and ``labels=`` for :func:`tonguevis.workflows.open_recording` from ``--audio``/``--labels``."""
    options = {}
    if getattr(args, "audio", None) is not None:
        options["audio"] = args.audio
    if getattr(args, "label_file", None) is not None:
        options["labels"] = args.label_file
    return options


def add_productions_from_argument(parser: argparse.ArgumentParser) -> None:
    """``--productions-from TIER``: productions from a label tier instead of the automatic segmentation."""
    parser.add_argument("--productions-from", metavar="TIER",
                        help="take the productions from this label tier (each non-empty interval is one; tiers "
                             "of --labels FILE, of NAME.TextGrid beside the recording, or MVIEW's words and "
                             "phones) instead of finding them from the tongue tip")


def add_run_arguments(parser: argparse.ArgumentParser, *, every: bool = False, modes_type=int,
                      quiet: bool = True) -> None:
    """The options of a run, the same (names, meanings, defaults) in every command that simulates (simulate,
    segment, energy, morph, batch, validate, view, export-video, live): each is a field of
    :class:`~tonguevis.sim.settings.RunSettings`, read back by :func:`run_settings_of`, and its default is the
    settings' own.  ``every``: the command reads several recordings (the rest is for each); ``modes_type``:
    the type of ``--modes`` (segment's keeps an old meaning for one release); ``quiet``: also ``--quiet``."""
    from tonguevis.sim.settings import METHODS, RunSettings

    defaults = RunSettings()
    group = parser.add_argument_group("how the tongue is simulated (the same options in every command that simulates)")
    group.add_argument("--mesh", type=Path, metavar="PATH",
                       help="tetrahedral tongue mesh (TetGen .node/.ele, VTU, Gmsh, .npz); default: the shipped tongue")
    group.add_argument("--mesh-axes", dest="mesh_axes", metavar="MAP",
                       help="axis mapping of --mesh into x anterior, y left, z up, e.g. -x,-z,-y (ArtiSynth); "
                            "the recording's axes are -O axes=MAP")
    group.add_argument("--axes", dest="mesh_axes", action=DeprecatedAlias, new="--mesh-axes")
    group.add_argument("--modes", type=modes_type, default=defaults.modes, metavar="M",
                       help=f"vibration modes (default {defaults.modes})")
    group.add_argument("--landmarks", choices=("speaker", "rule"), default=defaults.landmarks,
                       help="sensor nodes: snapped to the speaker's layout (default) or the paper's placement rule")
    group.add_argument("--method", choices=METHODS, default=None,
                       help="the tongue's physics: 'warped' (modal warping, the paper's; default), 'linear' (the "
                            "linear modal model) or 'domains' (the nonlinear StVK tongue of Luo et al. 2017 on "
                            "quadratic domains: slower, a few hundred frames/s, the modal methods thousands; "
                            "scripts/bench_domains.py)")
    group.add_argument("--linear", action="store_true", help="the linear modal model: --method linear")
    group.add_argument("--keep-volume", action="store_true",
                       help="keep the tongue's volume: each frame projected onto volume-preserving shapes (a "
                            "pressure projection, the sensor nodes held; any --method)")
    group.add_argument("--sensor-stiffness", type=sensor_stiffness_arg, default=defaults.sensor_stiffness,
                       metavar="K|hard",
                       help="how hard the sensor nodes are pulled onto the sensors, in units of the tongue's own "
                            "stiffness there (default 20: the tongue's most natural shape that follows them, "
                            "measured best on real recordings); 'hard' holds them exactly, as the paper")
    group.add_argument("--sensor-patches", type=_patch_radius_arg, nargs="?", const="default",
                       default=defaults.sensor_patches, metavar="MM",
                       help="put every sensor on the tongue's surface (the default): after the dynamics, the "
                            "tongue's own local deformation under each sensor (a patch of MM millimetres on the "
                            "model, default 3, fading out by 5/3 of it) closes the gap the modes leave (up to "
                            "2-6 mm on real recordings); the held-out sensors are predicted as without it")
    group.add_argument("--no-sensor-patches", dest="sensor_patches", action="store_const", const=None,
                       help="no patches: the sensor nodes only pulled by springs towards the sensors (the "
                            "sensors may float millimetres off the surface)")
    group.add_argument("--humps", action=argparse.BooleanOptionalAction, default=defaults.humps,
                       help="with the sensor patches, each sensor but the tip also lifts the tissue around it as a "
                            "hump (flattened against the palate when there is one), so a dorsum at /k/ rises as a "
                            "whole, not in a cone under its coil; --no-humps: the patches' local shapes alone "
                            f"(default: {'humps' if defaults.humps else 'no humps'})")
    group.add_argument("--fit-rest", dest="rest_fit", action="store_true",
                       help="bend the tongue so every sensor node sits on its rest sensor before simulating "
                            "(the tongue's own static response, jaw and hyoid held; its modes solved anew, "
                            "about 2 s): the rest shape the speaker's, not the generic one's")
    which = " (for every recording)" if every else ""
    group.add_argument("--rest", type=float, nargs=2, metavar=("START", "END"),
                       help=f"rest interval in seconds{which}; default: the longest still interval of >= 1 s, "
                            "else the stillest 0.2 s window (the summary says which)")
    group.add_argument("--palate", metavar="PALATE",
                       help=f"the speaker's palate{which} (a file made by `tonguevis palate` from trace "
                            "recordings) or 'generic': the tongue is kept below it and the contact is reported; "
                            "default: no contact (the generic palate is drawn only)")
    group.add_argument("--no-closures", dest="closures", action="store_false",
                       help="with --palate: do not press the tongue tip and blade onto the palate at each stop "
                            "closure found on the recording (by default a /t/ closure closes: the tip coil sits "
                            "some 10 mm behind the tip that makes it)")
    group.add_argument("--model-frame", dest="model_frame", action="store_const", const="model",
                       default=defaults.frame,
                       help="simulate in the generic tongue's frame and millimetres, the speaker scaled onto it "
                            "(the paper's way); default: the model placed in the speaker, every figure in the "
                            "speaker's millimetres")
    group.add_argument("--tongue-size", type=_tongue_size_arg, default=defaults.tongue_size,
                       metavar="X|adult|alignment",
                       help="the speaker's tongue as a multiple of the model's (1: the generic adult tongue, "
                            "turned and moved so the rest sensors lie on its surface); 'alignment': the size the "
                            "rest sensors' fit onto the model's nodes implies (the same motion as --model-frame in "
                            "the speaker's units); default 'adult': the alignment's size when it is an adult "
                            "tongue's (half to twice the model's volume), else the generic size (said when so)")
    if quiet:
        parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _tongue_size_arg(text: str):
    if text == "alignment":
        return None
    if text == "adult":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a multiple of the model's size, 'adult' or 'alignment', not {text!r}") from None
    if not (0.3 <= value <= 3.0):
        raise argparse.ArgumentTypeError(f"the tongue size must be between 0.3 and 3 times the model's, got {text}")
    return value


def _patch_radius_arg(text: str):
    if text == "default":
        return "default"
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a radius in millimetres, not {text!r}") from None
    if not (value > 0 and value < 50):
        raise argparse.ArgumentTypeError(f"the patch radius must be between 0 and 50 mm, got {text}")
    return value / 1000.0


def sensor_stiffness_arg(text: str):
    """``--sensor-stiffness`` value: a positive number, 'hard' (None) or 'default', the library's words
    (:func:`tonguevis.sensor_stiffness.sensor_stiffness_value`)."""
    from tonguevis.errors import SimulationError
    from tonguevis.sensor_stiffness import sensor_stiffness_value

    try:
        return sensor_stiffness_value(text)
    except SimulationError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def rest_arg(args) -> tuple[float, float] | None:
    """The ``--rest`` interval as (start_s, end_s), or None.

    Its order is checked here, before anything is read; whether it fits a
    recording is checked when that recording is simulated.
    """
    import math

    from tonguevis.errors import TonguevisError

    rest = getattr(args, "rest", None)
    if rest is None:
        return None
    start, end = float(rest[0]), float(rest[1])
    if not (math.isfinite(start) and math.isfinite(end) and start < end):
        files = [getattr(args, "file", None)] + [spec[0] for spec in (getattr(args, "source", None),
                                                                     getattr(args, "target", None)) if spec]
        files += list(getattr(args, "paths", None) or [])
        where = ", ".join(dict.fromkeys(str(f) for f in files if f is not None)) or None
        raise TonguevisError(f"--rest {start:g} {end:g}: the end must come after the start (seconds)", where)
    return start, end


def rest_line(motion) -> str:
    """The summary line saying which rest a motion used (e.g. ``rest: 2.31-2.51 s (stillest window: ...)``)."""
    from tonguevis.workflows import rest_of

    rest = rest_of(motion)
    return rest.describe() if rest is not None else "rest: not recorded in this motion file"


def read_recording_args(args):
    from tonguevis.workflows.recording import open_recording

    return open_recording(args.file, args.sensors, **reading_options(args))


def run_settings_of(args, **changes):
    """The :class:`~tonguevis.sim.settings.RunSettings` of a command's run options (:func:`add_run_arguments`),
    with ``changes`` (field -> value) on top.  A palate file is read now: a bad one is said before anything
    runs (one line, naming it)."""
    from tonguevis.sim.settings import RunSettings

    palate = args.palate
    if palate is not None and palate != "generic":
        from tonguevis.palate import load_palate

        palate = load_palate(palate)
    method = args.method or ("linear" if args.linear else None)
    return RunSettings(
        mesh=args.mesh, mesh_axes=args.mesh_axes, modes=args.modes, method=method, landmarks=args.landmarks,
        sensor_stiffness=args.sensor_stiffness, sensor_patches=args.sensor_patches, rest=rest_arg(args),
        palate=palate, frame=args.model_frame, tongue_size=args.tongue_size, keep_volume=args.keep_volume,
        rest_fit=args.rest_fit, closures=args.closures, humps=args.humps).replace(**changes)


def load_model_args(args):
    """The tongue model of ``--mesh``/``--mesh-axes``, else the shipped default."""
    from tonguevis.sim.settings import RunSettings, build_model

    return build_model(RunSettings(mesh=args.mesh, mesh_axes=args.mesh_axes))


def simulate_args(args, recording, model, progress=None, **changes):
    """Simulate with the command's settings (:func:`run_settings_of`, with ``changes``), with a tqdm bar
    (unless --quiet or a ``progress`` callback is given)."""
    from tonguevis._progress import tqdm_progress
    from tonguevis.sim.simulate import simulate

    settings = run_settings_of(args, **changes)
    if progress is not None:
        return simulate(recording, settings, model, progress=progress)
    with tqdm_progress("simulating", disable=getattr(args, "quiet", False)) as bar:
        return simulate(recording, settings, model, progress=bar)
