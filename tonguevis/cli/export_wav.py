"""``tonguevis export-wav FILE --out OUT.wav``: the sound and every sensor's x, y, z in one WAV for Praat.

Channel 1 is the sound (when the recording has one), then ``TT_x``, ``TT_y``, ``TT_z`` ... of every
sensor in millimetres, as IEEE float32 at the sound's rate (16 kHz without sound), head-corrected
like every other command; ``OUT.json`` beside it names each channel and its scale
(:mod:`tonguevis.workflows.ema_wav`).  In Praat: Open ▸ Read from file… OUT.wav, then View & Edit.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from tonguevis.cli._common import add_recording_arguments

    add_recording_arguments(parser)
    parser.add_argument("--out", type=Path, required=True, metavar="OUT.wav",
                        help="the WAV to write (its channel names go to OUT.json beside it)")
    parser.add_argument("--no-head-correction", action="store_true",
                        help="the positions as recorded even when head references exist")


def run(args: argparse.Namespace) -> int:
    from tonguevis.cli._common import read_recording_args
    from tonguevis.errors import TonguevisError
    from tonguevis.workflows.ema_wav import write_ema_wav

    if args.out.suffix.lower() != ".wav":  # said before the recording is read
        raise TonguevisError(f"the EMA export is a WAV: name it OUT.wav, not {args.out.name}", args.out)
    rec = read_recording_args(args)
    wav, side = write_ema_wav(rec, args.out, head_correction=not args.no_head_correction)
    import json

    sidecar = json.loads(side.read_text())
    names = [c["name"] for c in sidecar["channels"]]
    print(f"wrote {wav}: {len(names)} channels ({', '.join(names[:7])}{' ...' if len(names) > 7 else ''}), "
          f"float32 at {sidecar['rate_hz']:g} Hz, {sidecar['samples'] / sidecar['rate_hz']:.2f} s; EMA in mm, "
          f"{sidecar['frame']}")
    if sidecar["gaps_filled"]:
        print("gaps filled linearly: " + ", ".join(f"{n} ({len(g)})" for n, g in sidecar["gaps_filled"].items()))
    print(f"wrote {side} (the channels' names and scale)")
    return 0
