"""``tonguevis export-video``: simulate a recording and render it off screen to MP4 with its sound.

A recording without sound makes a silent MP4; the command says so and why.
"""

from __future__ import annotations

from pathlib import Path

from tonguevis.cli.view import COLOR_CHOICES, COLOR_HELP


def add_arguments(parser) -> None:
    from tonguevis.cli._common import (DeprecatedAlias, add_companion_arguments, add_reader_options_argument,
                                       add_run_arguments)

    parser.add_argument("file", nargs="?", type=Path, help="an EMA recording (default: the demo /ta/ train, spk1_ta)")
    parser.add_argument("--out", type=Path, required=True, metavar="MP4", help="the video to write")
    parser.add_argument("--start", type=float, metavar="S", help="first second (default: the start)")
    parser.add_argument("--end", type=float, metavar="S", help="last second (default: the end)")
    parser.add_argument("--sensors", metavar="MAP", help="sensor map: a preset or a JSON file of name -> channel")
    parser.add_argument("--fps", type=int, default=25, help="video frames per second (default 25)")
    parser.add_argument("--size", default="1280x720", metavar="WxH", help="video size in pixels (default 1280x720)")
    parser.add_argument("--color", choices=COLOR_CHOICES, default="displacement",
                        help=f"surface colouring (default: displacement; {COLOR_HELP})")
    parser.add_argument("--reference", choices=("head", "jaw"), default="head",
                        help="frame of reference: head (default: tongue and jaw move with the jaw, palate fixed) "
                             "or jaw (the jaw's motion removed, as simulated)")
    parser.add_argument("--frame", choices=("head", "jaw"), dest="reference", action=DeprecatedAlias,
                        new="--reference")  # its old name: in `view`, --frame is a frame number
    add_run_arguments(parser)
    add_reader_options_argument(parser)
    add_companion_arguments(parser, labels=False)  # the video has the sound, not the labels


def run(args) -> int:
    from tonguevis._progress import tqdm_progress
    from tonguevis.cli._common import reading_options, run_settings_of
    from tonguevis.errors import RecordingError
    from tonguevis.workflows.session import demo_recording_path, load_session
    from tonguevis.workflows.simulation import simulate_session
    from tonguevis.render.video import export_video

    path = args.file or demo_recording_path()
    if path is None:
        raise RecordingError("no file given and no demo recording in data/")
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        raise RecordingError(f"--size must look like 1280x720, got {args.size!r}") from None
    settings = run_settings_of(args)  # first: a bad palate or setting is said before anything runs
    options = reading_options(args)  # -O, then --audio FILE
    session = load_session(path, sensor_map=args.sensors, rest=settings.rest, **options)
    with tqdm_progress("simulating", disable=args.quiet) as progress:
        simulate_session(session, settings, progress=progress)
    with tqdm_progress("rendering", disable=args.quiet) as progress:
        out = export_video(session, args.out, args.start, args.end, fps=args.fps, size=(width, height),
                           mode=args.color, progress=progress, frame=args.reference)
    from tonguevis.render.mp4 import probe_streams

    if "audio" in probe_streams(out):  # what the file holds, not what was meant to go in
        print(f"{session.rest.describe()}\n{out} ({args.reference} frame, with the recording's sound"
              f"{sound_source(session.recording)})")
        return 0
    print(f"{session.rest.describe()}\n{out} ({args.reference} frame)")
    silent = silence_reason(session.recording, Path(path), audio_off=options.get("audio") is False)
    print(f"note: {out} is silent: {silent or 'the time range lies outside the sound of the recording'}")
    return 0


def sound_source(recording) -> str:
    """": from take.wav" / ": the file's own" for the line saying a video has sound; "" when unknown."""
    meta = recording.metadata
    if meta.get("audio_file"):
        return f": from {Path(str(meta['audio_file'])).name}"
    return ": the file's own" if meta.get("audio_source") == "embedded" else ""


def silence_reason(recording, path: Path, audio_off: bool = False) -> str | None:
    """Why the video of ``recording`` (read from ``path``) has no sound, or None when it has some."""
    if recording.audio is not None and len(recording.audio.samples):
        return None
    if audio_off:
        return "the sound was turned off (-O audio=false)"
    return (f"{path.name} holds no sound and no {path.stem}.wav lies beside it; give the recording's "
            "WAV with --audio FILE")
