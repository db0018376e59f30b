#!/usr/bin/env python
"""Benchmark the physics core against the paper's Table 1 (Yang et al. 2013).

On the ArtiSynth tongue (the paper's mesh, 1,803 nodes, 8,606 tets) when
../shared is present, else our shipped tongue; 100 modes; the demo recording
spk1_ta.  Prints and optionally writes (--json) throughput_fps (whole trial:
reduced integration plus every frame reconstructed on the full mesh),
frame_ms (one interactive frame: one reduced step plus one full-mesh warp),
cold_start_s (mesh -> modes, no cache), cache_load_s, and the warp-lang
kernels against their NumPy references.  Speed goals are checked here, never
in timed tests.

Contact (issue 26 item 5): ``contact_fps`` is simulate() end to end with a
palate (default: the demo with the generic palate on our shipped tongue, the
palate's tongue; --contact-recording and --palate for a speaker's, e.g. an
Opti-Speech /ta/ with the palate ``tonguevis palate`` fitted from its traces),
``contact_no_palate_fps`` the same run without it, ``contact_reference_fps``
the run with the contact on its NumPy reference (integration still compiled),
``contact_frames_solved`` the frames the contact solved (with forces in
the drive, corrected after the dynamics), ``contact_passes_per_frame_solved``
the QP passes they took (both stages) and ``contact_nnls_passes`` those left to
the NNLS (the others: guessed active sets, tonguevis.sim.contact._guessed_passes).
With ../shared present, the same figures for the Opti-Speech /ta/ 009 and /ka/ 006
against the palate fitted from the speaker's traces 002-004 (``contact_ta_009_*``,
``contact_ka_006_*``).

Measured 2026-12-03 on the 2 shared cores, the other core busy most of the time
(best of 5-7 runs, a run up to 40 % slower), q equal to the reference to 7e-13 and
3e-12 relative: /ka/ 006 from 3,260-3,330 frames/s (1.42 QP passes a frame solved,
all 2,601 by NNLS at ~0.1 ms each) to 4,670-5,080 (the same passes, none by NNLS),
/ta/ 009 from 3,040-3,190 to 4,270-4,780 (1.47 passes a frame, 872 by NNLS -> 0),
with the palate as fitted before commit df08e52's midline; with today's fit (more
contact: 2,131 and 723 frames solved, 1.8 passes a frame, 5 and 7 passes left to
the NNLS: ambiguous sets of near-duplicate rows) 3,990-4,150 and 3,960-4,060
frames/s (a loaded session: 1,690-1,750 and 1,640-1,730 before, 2,470-2,760 and
2,420-2,690 after; CPU time 2,500-2,600 -> 3,800-4,000).  The demo no longer
touches the generic palate at its defaults: 7,470-7,790 frames/s (no palate
11,400-12,050; the placed model's W no longer assembled per call).
Still under 5,000 on the real recordings: what bounds them (/ka/ 006, ~430-520 ms)
is the compiled frame loop (~110-120 ms, as without the palate), the figures with
the contact probe (~100 ms, 40 more than without), and the contact (~190-280 ms):
an all-frames clearance scan per stage (u = Φq and the query, ~25 ms each), the later
passes' queries (~40 ms), the guessed sets' rounds (~50-90 ms: a node a place added a round,
up to 6 rounds where 5 nodes press), the push guard (~12 ms).
2026-12-07 (issue 36, the palate at least half as fast as without it), the machine loaded
(load average 3.6-4.3 on the 2 cores, so the ratios say more than the rates): the guessed
rounds on K's factors, no (m, m) product per row or per sensor pattern (/ta/ 009 has 57),
10 rounds instead of 6 (passes left to the NNLS 122 -> 10 and 211 -> 4): /ta/ 009 815 against
1,498 frames/s without the palate (0.54; 975cf01 in the same session 791/1,582, 0.50), /ka/ 006
1,379/2,712 (0.51; 975cf01 1,149/2,495, 0.46); alternating runs in one process, best of 7, gave
0.48-0.57 wall and 0.53-0.54 CPU-time ratios (975cf01: 0.38-0.49, 0.44-0.49).  What bounds the
palate's share now (/ka/ 006, of ~0.7 s more than without it): the guessed rounds (~0.3 s over both
stages: the batched eigenvalues and solves, the product with Φ for w), the clearance queries of the
later passes with the products Φq before them (~0.15 s: warp's CPU kernel ~36 ns a point), the
correction after the dynamics (~0.2 s, the same solve again) and the figures' contact probe.
Later on 2026-12-07 the sensor humps became the default (and the estimated roof is raised broadly, so
more frames touch: 1,151 and 2,277 solved): the palate run now also projects the humps below the
palate (tonguevis.sim.patch_contact), and on a quiet machine /ta/ 009 runs at 483 against 1,832
frames/s (0.26) and /ka/ 006 at 647 against 3,035 (0.21).  Of /ka/ 006's 3.3 s with the palate the
projection takes 1.9 s (3,224 least distance problems on ~1,000 frames, NNLS ~0.3 ms each: 1.0 s),
the contact 0.7 s; --no-humps gives the figures above.
Later still (issue 36's speed work): the projection's least distance problems solved compiled, a pass's
at once (tonguevis.sim.least_distance_kernel: Goldfarb-Idnani, each problem started from its answer of the
pass before; 3-5 of 3,211 left to the NNLS on /ka/ 006), one BLAS thread, the modes' rotations applied by the
compiled R̃(w)d instead of (f, k, 3, 3) matrices: /ka/ 006's projection alone 1.9 s -> 0.5-0.7 s (0.21 s
of it the compiled solves), q within 1.4e-11 (relative) of before and closures.py's figures unchanged.
Measured with another session loading the 2 cores (load average 1.6-5.0; one run's no-palate rate on
/ta/ 009 was 1,057 frames/s, another's 1,972), so only ratios within a run say much: /ta/ 009 0.37, 0.38,
0.52 (725/1,969, 753/1,972, 554/1,057 frames/s), /ka/ 006 0.54, 0.44, 0.43 (1,065/1,970, 841/1,918,
839/1,935); the code before, in the same session, 0.26 (291/1,135) and 0.19 (347/1,788).  Alternating
free, new and previous projection in one process (best of 5, load average 2.5-3.0): /ta/ 009 1,228 / 573
/ 296 frames/s (0.47 against 0.24), /ka/ 006 1,876 / 823 / 393 (0.44 against 0.21).  What bounds
the palate's share now (/ta/ 009, ~1.1 s more than without it, profiled): the projection ~0.4 s (the
compiled solves 0.13 s, each pass's clearance query and rows, the first screening of every frame), the
contact ~0.4 s and its correction after the dynamics ~0.14 s (the guessed rounds' NumPy calls, spread
thin), the rest ~0.2 s.

Then (the same day) the dorsum is pressed at the /k/ closures as the tip is at /t/, the humps' projection
holds the pulled nodes in every frame (the pulled frames are projected too) and the correction after the
dynamics also holds the drawn (warped) shape: on a quiet machine (load average 0.2-1.5), two runs on
2f05fe3, /ta/ 009 682 and 769 against 1,965 and 1,982 frames/s (0.35, 0.39), /ka/ 006 949 and 935 against
2,985 and 3,020 (0.32, 0.31).  Of /ta/ 009's ~0.95 s more than without the palate (profiled): the
projection 0.35 s, the drive's contact solve 0.33 s, the correction after the dynamics 0.22 s (the drawn
check and its re-solve ~0.1 s of it), the palate's placement 0.07 s.  Of /ka/ 006's ~1.7 s: the contact
solve 0.78 s, the projection 0.63 s, the correction 0.40 s.  The >= 0.5 goal is not met.

Domains (issue 26 item 5): ``domains_fps`` is simulate(method="domains") end to end on the
demo (--recording) and our shipped tongue, default settings, best of 3 after a first call
that builds the domains (``domains_loop_fps`` its frame loop alone,
``domains_forces_per_frame`` the exact full-mesh forces it took); accuracy against the
reference solve in scripts/bench_domains.py.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
ARTISYNTH = REPO.parent / "shared" / "data" / "artisynth" / "tongue3.1.node"
PAPER_FPS = 36.3  # Table 1, simulation with GPU
PAPER_FRAME_MS = 27.5  # one interactive frame (DESIGN.md's reading of the paper's timings)


def best_of(fn, repeat=3):
    """Smallest wall time of ``repeat`` calls (seconds) and the last result."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", type=Path, help="mesh to use (default: ArtiSynth tongue if present, else ours)")
    parser.add_argument("--axes", help="axis mapping for --mesh")
    parser.add_argument("--recording", type=Path, default=REPO / "data" / "spk1_ta.tsv")
    parser.add_argument("--modes", type=int, default=100)
    parser.add_argument("--json", type=Path, help="write the figures here")
    parser.add_argument("--contact-recording", type=Path, help="recording for the contact figures (default: "
                        "--recording; on our shipped tongue, whatever --mesh)")
    parser.add_argument("--palate", default="generic", help="palate for the contact figures: 'generic' (default) "
                        "or a palate file from `tonguevis palate`")
    args = parser.parse_args(argv)

    os.environ["TONGUEVIS_CACHE"] = tempfile.mkdtemp(prefix="tonguevis-bench-")
    from tonguevis.io import read_recording
    from tonguevis.mesh import ARTISYNTH_AXES, read_mesh
    from tonguevis.preprocess import prepare_targets
    from tonguevis.sim import TongueModel
    from tonguevis.sim.newmark import NewmarkSettings, integrate
    from tonguevis.sim.newmark_kernel import integrate_compiled
    from tonguevis.sim.simulate import drive_schedule, simulate
    from tonguevis.sim.rotation import rotate_accumulated
    from tonguevis.sim.kernels import rotate_accumulated_compiled

    if args.mesh is not None:
        mesh_path, axes = args.mesh, args.axes
    elif ARTISYNTH.exists():
        mesh_path, axes = ARTISYNTH, ARTISYNTH_AXES
    else:
        mesh_path, axes = None, None
    mesh = read_mesh(mesh_path, axes=axes) if mesh_path else TongueModel.default().mesh
    mesh_name = str(mesh_path.name if mesh_path else "tonguevis default tongue")

    # Cold start: landmarks, assembly, eigen-solve (no cache), W.
    t0 = time.perf_counter()
    model = TongueModel.from_mesh(mesh)
    basis = model.basis(args.modes)
    model.rotation_matrix(basis)
    cold = time.perf_counter() - t0
    cache_load, _ = best_of(lambda: TongueModel(model.mesh, model.landmarks).basis(args.modes))

    rec = read_recording(args.recording, sensor_map=args.recording.parent / "sensor_map.json")
    prep = prepare_targets(rec, model)
    w_full = model.rotation_matrix(basis)
    dofs = (3 * prep.nodes[:, None] + np.arange(3)).ravel()
    s = len(prep.nodes)
    phi_s, w_s = basis.phi[dofs].reshape(s, 3, -1), w_full[dofs].reshape(s, 3, -1)
    settings = NewmarkSettings(dt=1 / rec.rate, alpha=model.material.alpha, beta=model.material.beta)
    frames = len(prep.displacement)
    # The default drive: targets projected onto the tongue's deformations (sensor springs), then held.
    t_proj, (targets, compliance, _) = best_of(
        lambda: drive_schedule(prep.displacement, rec.rate, basis.eigenvalues, phi_s, 20.0))
    integrate_compiled(basis.eigenvalues, phi_s, w_s, targets[:3], settings, compliance=compliance[:3])  # compile
    t_int, result = best_of(lambda: integrate_compiled(basis.eigenvalues, phi_s, w_s, targets, settings,
                                                       compliance=compliance))
    t_ref, ref = best_of(lambda: integrate(basis.eigenvalues, phi_s, w_s, targets, settings, compliance=compliance),
                         repeat=1)
    t_int += t_proj
    t_sim, _ = best_of(lambda: simulate(rec, model, modes=args.modes), repeat=2)
    model.displacements(result.q[:2])
    t_rec, _ = best_of(lambda: model.displacements(result.q))
    t_rec32, _ = best_of(lambda: model.displacements(result.q, dtype=np.float32))
    throughput = frames / (t_int + t_rec)
    throughput32 = frames / (t_int + t_rec32)

    # One interactive frame: one reduced step (the per-frame share of the compiled loop) + one full-mesh warp.
    q = result.q[int(np.argmax(model.energy(result.q)))]
    t_warp1, _ = best_of(lambda: model.displacement(q), repeat=50)
    frame_ms = 1e3 * (t_int / frames + t_warp1)

    contact = bench_contact(args.contact_recording or args.recording, args.palate, args.modes)
    contact.update(bench_contact_speech(args.modes))
    domains = bench_domains(args.recording)

    # Kernels against NumPy.
    rng = np.random.default_rng(0)
    w = rng.normal(size=(frames, mesh.n_nodes, 3)) * 0.2
    d = rng.normal(size=(frames, mesh.n_nodes, 3)) * 1e-3
    t_wk, fast = best_of(lambda: rotate_accumulated_compiled(w, d))
    t_np, slow = best_of(lambda: rotate_accumulated(w, d), repeat=1)

    figures = {
        "mesh": mesh_name,
        "mesh_nodes": mesh.n_nodes,
        "mesh_tets": mesh.n_tets,
        "modes": args.modes,
        "recording": args.recording.name,
        "frames": frames,
        "driving_sensors": prep.names,
        "throughput_fps": throughput,
        "throughput_float32_render_fps": throughput32,
        "integration_fps": frames / t_int,
        "projection_ms": 1e3 * t_proj,
        "simulate_end_to_end_fps": frames / t_sim,
        "integration_numpy_fps": frames / t_ref,
        "integration_max_rel_diff": float(np.abs(result.q - ref.q).max() / np.abs(ref.q).max()),
        "newton_iterations_mean": float(result.iterations.mean()),
        "reconstruction_fps": frames / t_rec,
        "reconstruction_float32_fps": frames / t_rec32,
        "frame_ms": frame_ms,
        "full_mesh_warp_ms": 1e3 * t_warp1,
        "cold_start_s": cold,
        "eigensolve_s": basis.info.get("solve_s", float("nan")),
        "cache_load_s": cache_load,
        "rotation_kernel_warp_s": t_wk,
        "rotation_kernel_numpy_s": t_np,
        "rotation_kernel_max_abs_diff": float(np.abs(fast - slow).max()),
        "throughput_vs_paper": throughput / PAPER_FPS,
        "frame_speedup_vs_paper": PAPER_FRAME_MS / frame_ms,
        **contact,
        **domains,
    }
    width = max(map(len, figures))
    for key, value in figures.items():
        text = f"{value:.4g}" if isinstance(value, float) else str(value)
        print(f"{key:<{width}}  {text}")
    print(f"\npaper (Table 1, 2012 GPU): {PAPER_FPS} frames/s; goals: >= 10,000 frames/s, <= 1 ms a frame, "
          "cold start <= 3 s, cache <= 0.3 s; with the palate >= 5,000 frames/s; domains >= 1,000 frames/s")
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))
    return 0


def bench_contact(recording_path: Path, palate, modes: int, palate_name: str | None = None) -> dict:
    """simulate() end to end on our shipped tongue with and without ``palate`` (best of 5 each), and
    with the contact's NumPy reference (once): frames per second, the frames the contact solved,
    the QP passes per frame solved and how many of them the NNLS took (the rest: guessed sets)."""
    import logging

    from tonguevis.io import read_recording
    from tonguevis.sim import TongueModel
    from tonguevis.sim.simulate import simulate

    mapping = recording_path.parent / "sensor_map.json"
    rec = read_recording(recording_path, sensor_map=mapping if mapping.exists() else None)
    model = TongueModel.default()
    logging.getLogger("tonguevis").setLevel(logging.ERROR)  # a raised palate or a rest stand-in, said once is enough
    simulate(rec, model, modes=modes, palate=palate)  # caches, compiled kernels
    t_free, _ = best_of(lambda: simulate(rec, model, modes=modes), repeat=5)
    t_contact, motion = best_of(lambda: simulate(rec, model, modes=modes, palate=palate), repeat=5)
    with _counted_passes() as passes:
        simulate(rec, model, modes=modes, palate=palate)
    reference = _contact_on_numpy()
    with reference:
        t_ref, ref = best_of(lambda: simulate(rec, model, modes=modes, palate=palate), repeat=1)
    logging.getLogger("tonguevis").setLevel(logging.NOTSET)
    frames = motion.n_frames
    c, r = motion.metadata["contact"], ref.metadata["contact"]
    solved = int(c["frames_with_contact_forces"] + c["frames_corrected_after_the_dynamics"])
    return {
        "contact_recording": recording_path.name,
        "contact_palate": palate_name or str(palate),
        "contact_fps": frames / t_contact,
        "contact_no_palate_fps": frames / t_free,
        "contact_reference_fps": frames / t_ref,
        "contact_frames_solved": solved,
        "contact_passes_per_frame_solved": passes["all"] / max(solved, 1),
        "contact_nnls_passes": passes["nnls"],
        "contact_max_rel_diff": float(np.abs(motion.q - ref.q).max() / np.abs(ref.q).max()),
        "contact_figures_as_reference": all(c[k] == r[k] for k in (
            "frames_in_contact", "frames_with_contact_forces", "frames_corrected_after_the_dynamics")),
    }


def bench_domains(recording_path: Path) -> dict:
    """simulate(method="domains") end to end on our shipped tongue (best of 3 after a first call that builds and
    caches the domains): frames per second of the whole call and of its frame loop, and the forces per frame."""
    import logging

    from tonguevis.io import read_recording
    from tonguevis.sim import TongueModel
    from tonguevis.sim.simulate import simulate

    mapping = recording_path.parent / "sensor_map.json"
    rec = read_recording(recording_path, sensor_map=mapping if mapping.exists() else None)
    model = TongueModel.default()
    logging.getLogger("tonguevis").setLevel(logging.ERROR)
    simulate(rec, model, method="domains")  # the weights' solve, the basis, the compiled kernels
    t, motion = best_of(lambda: simulate(rec, model, method="domains"))
    logging.getLogger("tonguevis").setLevel(logging.NOTSET)
    d = motion.metadata["domains"]
    return {
        "domains_fps": motion.n_frames / t,
        "domains_loop_fps": d["frames_per_s"],
        "domains_forces_per_frame": d["force_calls"] / motion.n_frames,
        "domains_dofs": d["dofs"],
    }


#: The real recordings of the contact figures (issue 26 item 5), with the speaker's palate fitted
#: from the same session's traces, when ../shared is present.
OPTISPEECH = REPO.parent / "shared" / "data" / "ema" / "optispeech"
SPEECH = {"ta_009": "009_OSN12_Tah_withFb_natural_HR.tsv", "ka_006": "006_OSN12_Kah_nofb_natural_take2_HR.tsv"}
TRACES = ("002_OSN12_Palate_MidSagital_HR.tsv", "003_OSN12_Palate_Coronal_HR.tsv", "004_OSN12_Palate_Scribble_HR.tsv")


def bench_contact_speech(modes: int) -> dict:
    """:func:`bench_contact` on Opti-Speech /ta/ 009 and /ka/ 006 with the palate fitted from the speaker's
    traces (``tonguevis palate`` 002-004), keys ``contact_<ta_009|ka_006>_...``; {} without ../shared."""
    if not all((OPTISPEECH / f).exists() for f in (*SPEECH.values(), *TRACES)):
        return {}
    from tonguevis.workflows.palate import palate_from_traces

    palate = palate_from_traces([OPTISPEECH / f for f in TRACES])
    out = {}
    for name, file in SPEECH.items():
        figures = bench_contact(OPTISPEECH / file, palate, modes, "speaker (traces 002-004)")
        out.update({f"contact_{name}_{key.removeprefix('contact_')}": value for key, value in figures.items()})
    return out


class _counted_passes:
    """Within it, the contact's QP passes are counted: {"all": every frame's passes, "nnls": those by NNLS}."""

    def __enter__(self):
        from tonguevis.sim import contact

        self.counts = {"all": 0, "nnls": 0}
        self.saved = contact._guessed_passes, contact._contact_pass_fast
        guessed, nnls = self.saved

        def count_guessed(solves, frames, *a, **k):
            self.counts["all"] += len(frames)  # each frame given takes one pass, guessed or by NNLS
            return guessed(solves, frames, *a, **k)

        def count_nnls(*a, **k):
            self.counts["nnls"] += 1
            return nnls(*a, **k)

        contact._guessed_passes, contact._contact_pass_fast = count_guessed, count_nnls
        return self.counts

    def __exit__(self, *exc):
        from tonguevis.sim import contact

        contact._guessed_passes, contact._contact_pass_fast = self.saved
        return False


class _contact_on_numpy:
    """Within it, simulate() solves the contact on its NumPy reference (the rest stays compiled)."""

    def __enter__(self):
        from tonguevis.sim import contact

        self.saved = contact.solve_contact, contact.correct_frames
        fixed = {"backend": "numpy"}
        contact.solve_contact = lambda *a, **k: self.saved[0](*a, **{**k, **fixed})
        contact.correct_frames = lambda *a, **k: self.saved[1](*a, **{**k, **fixed})
        return self

    def __exit__(self, *exc):
        from tonguevis.sim import contact

        contact.solve_contact, contact.correct_frames = self.saved
        return False


if __name__ == "__main__":
    sys.exit(main())
