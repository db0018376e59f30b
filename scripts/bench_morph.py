#!/usr/bin/env python
"""Morph frames per second on the paper-size mesh with 100 modes, against the paper's 157.5 FPS.

Mesh: the ArtiSynth tongue (the paper's, 1,803 nodes, 8,606 tets) from
../shared/data when present (only read, never copied), else our shipped tongue.
A morph frame is the blend q(t) = (1 - t) q_source + t q_target, its warped
reconstruction on every node and the per-element colour (eq. 14 through the
empirical CDF).  The colour depends only on the two ends, so it is computed
once per source/target pair ("setup", together with Φq and Wq of the two
ends) and reported apart; ``morph_fps`` is the steady rate of frames
(batch of --frames blends, float32 output as the renderer uses),
``morph_fps_with_setup`` the rate of a 60-frame morph including its setup,
``slider_frame_ms`` one frame at a time (dragging the blend slider).

    python scripts/bench_morph.py [--json OUT] [--frames 2000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
ARTISYNTH = REPO.parent / "shared" / "data" / "artisynth" / "tongue3.1.node"
PAPER_FPS = 157.5
GOAL_FPS = 5000.0


def paper_size_model(ours: bool = False):
    """(model, description): the ArtiSynth tongue when available (and not ``ours``), else ours."""
    from tonguevis.sim import TongueModel

    if ARTISYNTH.exists() and not ours:
        from tonguevis.mesh.axes import ARTISYNTH_AXES
        from tonguevis.mesh.readers import read_mesh

        mesh = read_mesh(ARTISYNTH, axes=ARTISYNTH_AXES)
        try:
            from tonguevis.mesh import find_landmarks

            landmarks = find_landmarks(mesh)
        except ImportError:  # landmark finder not available: five lowest posterior nodes as anchors
            p = mesh.points
            anchors = np.argsort(p[:, 2] + 0.3 * (p[:, 0] - p[:, 0].max()))[:5]
            landmarks = SimpleNamespace(sensors={"TT": int(np.argmax(p[:, 0]))}, anchors=anchors)
        return TongueModel(mesh, landmarks), f"ArtiSynth tongue3.1 ({ARTISYNTH})"
    return TongueModel.default(), "tonguevis shipped tongue (meshes/)"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, help="write the figures as JSON")
    parser.add_argument("--frames", type=int, default=2000, help="blends per batch (default 2000)")
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats, best kept (default 5)")
    parser.add_argument("--modes", type=int, default=100)
    parser.add_argument("--ours", action="store_true", help="use our shipped tongue even when the ArtiSynth one is there")
    args = parser.parse_args(argv)

    from tonguevis.analysis.morph import Morph
    from tonguevis.analysis.morph_kernels import MorphKernel

    model, mesh_name = paper_size_model(args.ours)
    t0 = time.perf_counter()
    basis = model.basis(args.modes)
    model.rotation_matrix(basis)
    basis_s = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    scale = 2e-3 / np.sqrt(np.maximum(basis.eigenvalues / basis.eigenvalues[0], 1.0))
    q_source, q_target = rng.normal(size=(2, args.modes)) * scale
    Morph(model, q_source, q_target).displacements([0.5])  # warm-up: kernel load

    def setup():
        morph = Morph(model, q_source, q_target)
        morph._kernel = MorphKernel(morph._lin[0], morph._lin[1], morph._rot[0], morph._rot[1])
        morph.element_difference  # needs the two ends' warped displacement
        morph.element_colour
        return morph

    setup_times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        morph = setup()
        setup_times.append(time.perf_counter() - t0)
    setup_s = min(setup_times)

    ts = np.linspace(0.0, 1.0, args.frames)
    batch = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        morph._kernel.frames(ts, dtype=np.float32)
        batch.append(time.perf_counter() - t0)
    morph_fps = args.frames / min(batch)

    with_setup = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        m = setup()
        m._kernel.frames(np.linspace(0, 1, 60), dtype=np.float32)
        with_setup.append(time.perf_counter() - t0)
    fps_with_setup = 60 / min(with_setup)

    single = []
    for t in np.linspace(0, 1, 200):
        t0 = time.perf_counter()
        morph._kernel.frames([t], dtype=np.float32)
        single.append(time.perf_counter() - t0)
    slider_ms = 1e3 * float(np.median(single))

    result = {
        "mesh": mesh_name,
        "nodes": int(model.mesh.n_nodes),
        "tets": int(model.mesh.n_tets),
        "modes": int(args.modes),
        "frames_per_batch": int(args.frames),
        "morph_fps": morph_fps,
        "morph_frame_us": 1e6 / morph_fps,
        "morph_fps_with_setup": fps_with_setup,
        "setup_ms": 1e3 * setup_s,
        "slider_frame_ms": slider_ms,
        "paper_fps": PAPER_FPS,
        "ratio_to_paper": morph_fps / PAPER_FPS,
        "goal_fps": GOAL_FPS,
        "meets_goal": bool(morph_fps >= GOAL_FPS),
        "basis_s": basis_s,
        "device": str(morph._kernel.device),
        "cpu_count": os.cpu_count(),
    }
    print(f"mesh: {mesh_name}: {result['nodes']} nodes, {result['tets']} tets, {args.modes} modes, "
          f"warp device {result['device']}")
    print(f"morph frames: {morph_fps:,.0f} frames/s ({result['morph_frame_us']:.0f} µs/frame, "
          f"batch of {args.frames}); paper {PAPER_FPS} frames/s -> x{result['ratio_to_paper']:.0f}; "
          f"goal {GOAL_FPS:,.0f}: {'met' if result['meets_goal'] else 'NOT met'}")
    print(f"per source/target pair setup (ends, eq. 14, CDF colours): {result['setup_ms']:.2f} ms; "
          f"a 60-frame morph with its setup: {fps_with_setup:,.0f} frames/s; "
          f"one slider frame: {slider_ms:.3f} ms")
    if args.json:
        tmp = args.json.with_suffix(args.json.suffix + ".tmp")
        tmp.write_text(json.dumps(result, indent=1) + "\n")
        os.replace(tmp, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
