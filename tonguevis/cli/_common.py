"""Arguments and steps that several commands share: reading a recording, the model, simulating."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_recording_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, help="an EMA recording (NDI Wave TSV, Carstens .pos, EST .ema, MVIEW .mat, BVH, CSV)")
    parser.add_argument("--sensors", metavar="MAP",
                        help="sensor map: a preset (paper, haskins, mngu0) or a JSON file of name -> channel "
                             "(default: sensor_map.json beside the file, if there is one)")


def add_model_arguments(parser: argparse.ArgumentParser, modes: int = 100) -> None:
    parser.add_argument("--mesh", type=Path, metavar="PATH",
                        help="tetrahedral tongue mesh (TetGen .node/.ele, VTU, Gmsh); default: the shipped tongue")
    parser.add_argument("--axes", metavar="MAP",
                        help="axis mapping of --mesh into x anterior, y left, z up, e.g. -x,-z,-y (ArtiSynth)")
    parser.add_argument("--modes", type=int, default=modes, metavar="M", help=f"vibration modes (default {modes})")
    parser.add_argument("--landmarks", choices=("speaker", "rule"), default="speaker",
                        help="sensor nodes: snapped to the speaker's layout (default) or the paper's placement rule")
    parser.add_argument("--linear", action="store_true", help="linear modal model (no modal warping)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def read_recording_args(args):
    from tonguevis.io import read_recording

    return read_recording(args.file, sensor_map=args.sensors)


def load_model_args(args):
    """The tongue model of ``--mesh``/``--axes``, else the shipped default."""
    from tonguevis.sim import TongueModel

    if getattr(args, "mesh", None) is None:
        return TongueModel.default()
    options = {"axes": args.axes} if getattr(args, "axes", None) else {}
    return TongueModel.from_mesh(args.mesh, **options)


def simulate_args(args, recording, model):
    """Simulate with a tqdm bar (unless --quiet)."""
    from tonguevis._progress import tqdm_progress
    from tonguevis.sim import simulate

    with tqdm_progress("simulating", disable=getattr(args, "quiet", False)) as progress:
        return simulate(recording, model, modes=args.modes, warping=not getattr(args, "linear", False),
                        landmarks=getattr(args, "landmarks", "speaker"), progress=progress)
