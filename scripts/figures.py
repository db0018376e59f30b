#!/usr/bin/env python
"""Regenerate the paper's Figs. 13 and 14 (and a morph strip, Fig. 15) on the demo corpus.

    python scripts/figures.py [--data data] [--out docs/images] [--mesh PATH --axes MAP] [--modes 100]

Every demo recording (``data/spk*_*.tsv``, SYNTHETIC) is simulated on the
shipped tongue model (or ``--mesh``), its productions are found (§3.2; the
2nd-4th of each train) and cut into energy curves U(t) = ½ qᵀΛq.

* ``fig13_mds_energy.png``: top, SMACOF MDS of the frames of four motions
  (one train each of /ta/ /ka/ /la/ /ra/ of spk1), consecutive frames joined:
  the axes mean nothing and the sequences tangle; bottom, the same four
  motions as energy against time, which read at a glance.
* ``fig14_energy_curves.png``: nine curves, three productions each of spk1
  /la/, spk1 /ka/ and spk2 /ka/ (the paper's native /la/, native /ka/ and
  non-native /ka/), on normalised time.
* ``fig14_all_speakers.png``: every production of every speaker, one panel
  per syllable, group means bold.
* ``fig14_vowel_windows.png``: the same on vowel-to-vowel windows, which put
  the consonant closure mid-curve (closer to how the paper's Fig. 14 reads).
* ``morph_la_ka.png``: a morph from spk1 /la/ to spk1 /ka/ at their energy
  peaks, coloured by eq. (14); ``morph_la_ka_node_mean.png`` by the
  size-independent mean squared node distance.

Prints the per-group statistics (peak, time of peak, area).  Figures derived
from third-party meshes must not be committed: use the shipped mesh for docs/.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

SPEAKER_COLOURS = {"spk1": "#1f77b4", "spk2": "#d62728", "spk3": "#2ca02c"}
SYLLABLE_COLOURS = {"ta": "#1f77b4", "ka": "#d62728", "la": "#2ca02c", "ra": "#9467bd"}


def simulate_corpus(data: Path, model, modes: int):
    from tonguevis._progress import tqdm_progress
    from tonguevis.analysis.corpus import load_corpus
    from tonguevis.workflows.corpus import corpus_energy_curves

    corpus = load_corpus(sorted(data.glob("spk*_*.tsv")))
    t0 = time.perf_counter()
    with tqdm_progress("simulating the demo corpus") as progress:
        result = corpus_energy_curves(corpus, model=model, modes=modes, progress=progress)
    print(f"simulated {len(corpus)} recordings in {time.perf_counter() - t0:.1f} s; {len(result.curves)} curves")
    return result


def vowel_curves(result, data: Path):
    """The same productions on vowel-to-vowel windows (consonant mid-curve), from the simulated motions."""
    from tonguevis.analysis.corpus import labels_from_name
    from tonguevis.analysis.energy import production_curves, vowel_windows
    from tonguevis.workflows import find_recording_productions, open_recording

    curves = []
    for name, motion in result.motions.items():
        entry = labels_from_name(data / f"{name}.tsv")
        rec = open_recording(entry.path)
        windows = [w for w in vowel_windows(find_recording_productions(rec, keep=None)) if 2 <= w.index <= 4]
        curves += production_curves(motion, windows, recording=name, speaker=entry.speaker, syllable=entry.syllable)
    return curves


def print_summary(curves, title: str) -> None:
    from tonguevis.analysis.energy import summarize

    print(f"\n{title} (mean ± sd over productions; time of peak normalised 0-1):")
    print(f"{'speaker':<8}{'syll':<6}{'n':>3}  {'peak mJ':>16}  {'peak at':>12}  {'area mJ·s':>16}  {'duration s':>12}")
    for g in summarize(curves, ("speaker", "syllable")):
        m, s = g.mean, g.std
        print(f"{g.key[0]:<8}{g.key[1]:<6}{g.n:>3}  {1e3 * m['peak_J']:>8.3f} ± {1e3 * s['peak_J']:<6.3f}"
              f"  {m['peak_time_norm']:>5.2f} ± {s['peak_time_norm']:<4.2f}"
              f"  {1e3 * m['area_Js']:>8.4f} ± {1e3 * s['area_Js']:<6.4f}  {m['duration_s']:>5.3f} ± {s['duration_s']:.3f}")


def fig14_vowel(curves, out: Path) -> None:
    from matplotlib.figure import Figure

    from tonguevis.analysis.energy import summarize
    from tonguevis.render.energy import plot_energy_curves, save_figure

    fig = Figure(figsize=(13, 8), layout="constrained")
    axes = fig.subplots(2, 2).ravel()
    for ax, syllable in zip(axes, ("ta", "ka", "la", "ra")):
        chosen = [c for c in curves if c.syllable == syllable]
        plot_energy_curves(ax, chosen, ("speaker",), normalised=True,
                           colours={(s,): c for s, c in SPEAKER_COLOURS.items()}, linewidth=0.6, alpha=0.35)
        for g in summarize(chosen, ("speaker",)):
            ax.plot(g.grid, 1e3 * g.mean_curve, color=SPEAKER_COLOURS[g.key[0]], lw=2.6)
        ax.set_xlabel("normalised time, previous vowel → own vowel (the consonant in the middle)")
        ax.set_title(f"/{syllable}/, vowel-to-vowel windows")
    fig.suptitle("Every production (thin) and each speaker's mean (bold), consonant mid-window")
    save_figure(fig, out / "fig14_vowel_windows.png", dpi=100)
    print_summary(curves, "vowel-to-vowel windows, per speaker and syllable")


def fig13(result, out: Path) -> None:
    from matplotlib.figure import Figure

    from tonguevis.render.energy import plot_mds_paths, save_figure
    from tonguevis.analysis.mds import frame_dissimilarities, smacof

    blocks, labels, energies, times = [], [], [], []
    for syllable in ("ta", "ka", "la", "ra"):
        name = f"spk1_{syllable}"
        curves = [c for c in result.curves if c.recording == name and c.train == 2]
        frames = np.arange(curves[0].frames[0], curves[-1].frames[-1] + 1)
        motion = result.motions[name]
        blocks.append(motion.q[frames])
        energies.append(motion.energy[frames])
        times.append(motion.times[frames] - motion.times[frames[0]])
        labels.append(f"spk1 /{syllable}/, train 2, productions 2-4")
    q = np.concatenate(blocks)
    segments, start = [], 0
    for b in blocks:
        segments.append((start, start + len(b)))
        start += len(b)
    t0 = time.perf_counter()
    mds = smacof(frame_dissimilarities(q), 2, init="random", random_state=0, max_iter=500, tol=1e-9)
    print(f"Fig. 13 MDS: {len(q)} frames, {mds.n_iter} SMACOF iterations in {time.perf_counter() - t0:.2f} s, "
          f"stress-1 {mds.stress1:.3f} (monotone: {bool(np.all(np.diff(mds.stress_history) <= 1e-12 * mds.stress_history[0]))})")
    colours = [SYLLABLE_COLOURS[s] for s in ("ta", "ka", "la", "ra")]
    fig = Figure(figsize=(8, 9), layout="constrained")
    top, bottom = fig.subplots(2, 1)
    plot_mds_paths(top, mds.embedding, segments, labels, colours)
    top.set_title("MDS (SMACOF) of the frames, consecutive frames joined: the order is lost")
    for e, t, label, colour in zip(energies, times, labels, colours):
        bottom.plot(t, 1e3 * e, color=colour, lw=1.4, label=label)
    bottom.set_xlabel("time since the first production's release (s)")
    bottom.set_ylabel("elastic energy U = ½ qᵀΛq (mJ)")
    bottom.set_title("Energy-time curves of the same four motions")
    bottom.grid(True, alpha=0.3)
    bottom.legend(fontsize="small", frameon=False)
    save_figure(fig, out / "fig13_mds_energy.png", dpi=110)


def fig14(result, out: Path) -> None:
    from matplotlib.figure import Figure

    from tonguevis.analysis.energy import summarize
    from tonguevis.render.energy import plot_energy_curves, save_figure

    nine = []
    for speaker, syllable in (("spk1", "la"), ("spk1", "ka"), ("spk2", "ka")):
        chosen = [c for c in result.curves if c.speaker == speaker and c.syllable == syllable and c.train == 3]
        nine += chosen[:3]
    fig = Figure(figsize=(8, 5), layout="constrained")
    ax = fig.subplots()
    colours = {("spk1", "la"): SYLLABLE_COLOURS["la"], ("spk1", "ka"): SYLLABLE_COLOURS["ka"], ("spk2", "ka"): "#ff9896"}
    plot_energy_curves(ax, nine, ("speaker", "syllable"), normalised=True, colours=colours, linewidth=1.6)
    ax.set_title("Nine productions (train 3, productions 2-4): spk1 /la/, spk1 /ka/, spk2 /ka/ (weaker /k/)")
    save_figure(fig, out / "fig14_energy_curves.png", dpi=110)

    fig = Figure(figsize=(13, 8), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax, syllable in zip(axes, ("ta", "ka", "la", "ra")):
        curves = [c for c in result.curves if c.syllable == syllable]
        plot_energy_curves(ax, curves, ("speaker",), normalised=True, colours={(s,): c for s, c in SPEAKER_COLOURS.items()},
                           linewidth=0.6, alpha=0.35)
        for g in summarize(curves, ("speaker",)):
            ax.plot(g.grid, 1e3 * g.mean_curve, color=SPEAKER_COLOURS[g.key[0]], lw=2.6)
        ax.set_title(f"/{syllable}/, release-to-release productions")
    fig.suptitle("Every production (thin) and each speaker's mean (bold)")
    save_figure(fig, out / "fig14_all_speakers.png", dpi=100)

    print_summary(result.curves, "release-to-release productions, per speaker and syllable")


def morph_figure(result, out: Path) -> None:
    from tonguevis.analysis.morph import morph_between
    from tonguevis.render.morph import render_png

    def peak(name):
        curve = max((c for c in result.curves if c.recording == name and c.train == 3), key=lambda c: c.energy.max())
        return curve.times[int(np.argmax(curve.energy))]

    src, tgt = result.motions["spk1_la"], result.motions["spk1_ka"]
    for difference, name in (("eq14", "morph_la_ka.png"), ("node_mean", "morph_la_ka_node_mean.png")):
        morph = morph_between(src, peak("spk1_la"), tgt, peak("spk1_ka"), difference=difference)
        morph.labels = (f"spk1 /la/ @ {src.times[morph.source_frame]:.2f} s",
                        f"spk1 /ka/ @ {tgt.times[morph.target_frame]:.2f} s")
        render_png(morph, out / name, title="q(t) = (1-t) q_source + t q_target")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO / "data")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "images")
    parser.add_argument("--mesh", type=Path, help="another tongue mesh (default: the shipped one)")
    parser.add_argument("--axes", help="axis mapping of --mesh, e.g. -x,-z,-y")
    parser.add_argument("--modes", type=int, default=100)
    parser.add_argument("--no-morph", action="store_true", help="skip the morph strip")
    args = parser.parse_args(argv)

    from tonguevis.sim import TongueModel

    if args.mesh is None:
        model = TongueModel.default()
    else:
        model = TongueModel.from_mesh(args.mesh, **({"axes": args.axes} if args.axes else {}))
    args.out.mkdir(parents=True, exist_ok=True)
    result = simulate_corpus(args.data, model, args.modes)
    fig13(result, args.out)
    fig14(result, args.out)
    fig14_vowel(vowel_curves(result, args.data), args.out)
    if not args.no_morph:
        morph_figure(result, args.out)
    print(f"\nwrote figures to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
