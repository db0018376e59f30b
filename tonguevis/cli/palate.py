"""``tonguevis palate TRACE... --out PALATE``: the speaker's palate from palate-trace recordings.

Reads each trace recording (any format; a probe sensor drawn along the
palate: Opti-Speech calls it PROBE), head-corrects it like the speech
recordings of the same session, fits one smooth surface to all the probe's
positions (:func:`tonguevis.palate.fit_palate`: outliers dropped, mirrored
about the midline, never extrapolated beyond the traced footprint) and writes
it as a surface mesh in the recordings' own frame (metres) with its grid
beside it (``PALATE.palate.npz``).  ``tonguevis simulate REC --palate PALATE``
then keeps the tongue below it.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("traces", type=Path, nargs="+", metavar="TRACE", help="palate-trace recordings")
    parser.add_argument("--out", type=Path, required=True, metavar="PALATE",
                        help="surface mesh to write (.stl, .obj, .vtk, .ply ...)")
    parser.add_argument("--probe", default="PROBE", metavar="SENSOR",
                        help="the sensor drawn along the palate (default PROBE, Opti-Speech's name)")
    parser.add_argument("--sensors", metavar="MAP", help="sensor map (preset or JSON) for the trace recordings")
    from tonguevis.cli._common import add_reader_options_argument

    add_reader_options_argument(parser, " of every trace")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from tonguevis.palate import check_mesh_path
    from tonguevis.workflows.palate import palate_from_traces

    check_mesh_path(args.out)
    from tonguevis.cli._common import parse_options

    surface = palate_from_traces(args.traces, args.probe, args.sensors, read_options=parse_options(args.option))
    for path, count in surface.metadata["samples"].items():
        print(f"{path}: {count} probe samples")
    for path, said in (surface.metadata.get("trace_registration_mm") or {}).items():
        if isinstance(said, dict):  # registered to the other traces by its shape (or not: too far off)
            print(f"{path}: {said['by']}: moved up to {said['largest_move_mm']:.1f} mm, turned "
                  f"{said['turn_deg']:.1f}°; RMS to the other traces {said['rms_to_the_others_mm'][0]:.2f} -> "
                  f"{said['rms_to_the_others_mm'][1]:.2f} mm")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    surface.save(args.out)
    meta = surface.metadata
    extent = np.isfinite(surface.z)
    xs = surface.x[np.any(extent, axis=0)]
    print(f"palate: {meta['kept']} of {meta['points']} trace points kept (outliers dropped), RMS distance to the "
          f"surface {1e3 * meta['rms_m']:.2f} mm; midline y = {1e3 * meta['midline_y']:.1f} mm; "
          f"{1e3 * (xs.max() - xs.min()):.0f} mm front to back")
    if "min_bend_radius_m" in meta:
        print(f"no fold: smoothed until it bends nowhere tighter than {1e3 * meta['min_bend_radius_m']:.0f} mm "
              f"(tightest bend {1e3 * meta['bend_radius_m']:.1f} mm, smoothing {meta['smoothing']:.2g} m²); "
              "simulations join it to the generic palate behind it")
    print(f"wrote {args.out} and {args.out.with_name(args.out.stem + '.palate.npz')} (the recordings' frame, metres)")
    return 0
