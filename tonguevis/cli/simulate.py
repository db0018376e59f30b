"""``tonguevis simulate FILE``: drive the tongue model with a recording and summarise the motion."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from tonguevis.sim.plausibility import plausibility_line

from tonguevis.cli._common import (
    add_recording_arguments, add_run_arguments, load_model_args, read_recording_args, rest_line, simulate_args,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_recording_arguments(parser)
    add_run_arguments(parser)
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help="write motion.npz here: q(t), times, per-frame figures, metadata and the model (any "
                             "frame is rebuilt from it: Motion.load); a few MB per minute of recording")
    parser.add_argument("--paraview", action="store_true",
                        help="with --out: also motion.xdmf + motion.h5 for ParaView, the mesh once and every "
                             "frame's displacement (float32, head frame) in one file")
    parser.add_argument("--surface-only", action="store_true",
                        help="with --paraview: the tongue's surface triangles only (about 40 %% of the bytes)")
    parser.add_argument("--frame-stride", type=int, default=1, metavar="N",
                        help="ParaView/VTK exports: every N-th frame (default 1: all)")
    parser.add_argument("--epg", type=Path, metavar="OUT",
                        help="with --palate: the virtual electropalatogram of every frame (the Reading EPG's 62 "
                             "electrodes on the palate, 1 where the tongue touches, and the percentage of contact, "
                             "centre of gravity, anteriority and posteriority) as CSV, or Parquet for .parquet")
    parser.add_argument("--vtk-series", action="store_true",
                        help="with --out: also the old vtk/ series, one .vtu file per frame (about 210 KB a frame: "
                             "large for long recordings)")


def _stiffness_text(meta: dict) -> str:
    k = meta.get("sensor_stiffness")
    if k is None:
        return "sensors held exactly (--sensor-stiffness hard, the paper)"
    return f"sensor springs {k:g}x the tongue's stiffness there: the tongue's most natural shape near the sensors"


def _modes_text(motion) -> str:
    from tonguevis.sim.patches import modes_text, physics_text

    return f"{modes_text(motion)}, {physics_text(motion)}"


def summary(motion) -> list[str]:
    """The lines ``tonguevis simulate`` prints."""
    from tonguevis.sim.placement import describe_fit

    res = np.nanmax(motion.sensor_residual) if np.isfinite(motion.sensor_residual).any() else float("nan")
    peak = int(np.argmax(motion.energy))
    end = motion.displacement(motion.n_frames - 1)
    meta = motion.metadata
    unconverged = len(meta.get("unconverged_frames", []))
    lines = [
        f"model: {motion.model.mesh.n_nodes} nodes, {motion.model.mesh.n_tets} tets, {_modes_text(motion)}; "
        f"sensor nodes: {meta['landmarks']}",
        rest_line(motion),
        "driving sensors: " + ", ".join(f"{n}->node {int(k)}" for n, k in zip(motion.sensor_names, motion.sensor_nodes)),
        (describe_fit(meta["fit"]) if "fit" in meta else  # motions saved before the speaker frame
         f"alignment: scale {meta['alignment_scale']:.3f}, rest fit RMS {1e3 * meta['alignment_rms_m']:.2f} mm")
        + (" (midsagittal fit)" if meta.get("midsagittal_alignment") else ""),
        f"frames: {motion.n_frames} ({motion.times[-1] - motion.times[0]:.2f} s); "
        f"Newton iterations per frame: {meta['newton_iterations_mean']:.2f}; unconverged frames: {unconverged}",
        f"max sensor residual: {1e3 * res:.2e} mm ({_stiffness_text(meta)})",
        plausibility_line(meta),
        f"max volume change: {100 * np.abs(motion.volume_change).max():.2f} % "
        f"(mean {100 * np.abs(motion.volume_change).mean():.2f} %)",
        f"energy peak: {1e3 * motion.energy[peak]:.3f} mJ at {motion.times[peak]:.2f} s",
        f"drift at the end: {1e3 * np.linalg.norm(end, axis=1).max():.3f} mm (largest node displacement, last frame)",
    ]
    if "contact" in meta:
        from tonguevis.sim.plausibility import contact_line

        lines.append(contact_line({**meta, "sensor_names": list(motion.sensor_names)}))
        from tonguevis.analysis.section import MidlineProfile

        closest = MidlineProfile(motion.model).closest_approach(motion)  # what the Palate tab plots, over time
        if closest is not None:
            lines.append(f"midline: closest to the palate {closest[0]:.1f} mm, {closest[1]:.0f} mm behind the tip, "
                         f"at {closest[2]:.2f} s")
    if meta.get("ignored_sensors"):
        lines.append("ignored (no landmark on the model): " + ", ".join(meta["ignored_sensors"]))
    return lines


def epg_lines(motion, recording, out) -> list[str]:
    """Write the motion's palatogram (every frame) to ``out``; the lines saying it and each production's at its
    closure (the productions as every command finds them)."""
    from tonguevis.analysis.epg import palatogram, production_epg, table_columns
    from tonguevis.preprocess.gesture_table import write_rows
    from tonguevis.workflows.recording import find_recording_productions

    gram = palatogram(motion)
    written = write_rows(gram.rows(), table_columns(), out)
    lines = [f"wrote {written}: the palatogram of {len(gram.times)} frames (62 electrodes and the EPG indices)"]
    table = find_recording_productions(recording, keep=None)
    for production, epg in zip(table, production_epg(motion, table)):
        if np.isfinite(epg["epg_frame_s"]):
            lines.append(f"  {production.name:<10} at {epg['epg_frame_s']:.2f} s: contact "
                         f"{epg['epg_percent_contact']:.0f} %, centre of gravity {epg['epg_cog']:.2f}, anteriority "
                         f"{epg['epg_anteriority']:.2f}, posteriority {epg['epg_posteriority']:.2f}")
    return lines


def run(args: argparse.Namespace) -> int:
    from tonguevis.errors import TonguevisError

    if args.out is None and (args.paraview or args.vtk_series):
        raise TonguevisError("--paraview and --vtk-series write into the folder given by --out DIR")
    if args.frame_stride < 1:
        raise TonguevisError(f"--frame-stride must be at least 1, got {args.frame_stride}")
    if args.epg is not None and args.palate is None:
        raise TonguevisError("--epg needs --palate: the palatogram is where the tongue touches the palate "
                             "(the speaker's from `tonguevis palate`, or generic)")
    recording = read_recording_args(args)
    model = load_model_args(args)
    motion = simulate_args(args, recording, model)
    lines = summary(motion)
    if args.epg is not None:
        lines += epg_lines(motion, recording, args.epg)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        motion.save(args.out / "motion.npz")
        written = [args.out / "motion.npz"]
        if args.paraview:
            from tonguevis.sim.xdmf import write_xdmf

            written.append(write_xdmf(motion, args.out / "motion.xdmf", surface_only=args.surface_only,
                                      stride=args.frame_stride))
        if args.vtk_series:
            written.append(motion.to_vtk_series(args.out / "vtk", frames=slice(None, None, args.frame_stride)))
        lines.append("wrote " + ", ".join(str(p) for p in written))
    print("\n".join(lines))
    return 0 if not motion.metadata.get("unconverged_frames") else 1
