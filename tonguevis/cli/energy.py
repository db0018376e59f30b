"""``tonguevis energy PATHS... --csv OUT [--png OUT]``: energy-time curves of productions (§6.3).

PATHS are recordings or folders (walked recursively).  Each recording is
simulated on the tongue model, cut into CV productions (the 2nd-4th of each
train unless ``--all``), and every production's elastic energy U = ½ qᵀΛq is
written in long format: one row per frame with the columns
``recording,production,time_s,time_norm,energy_J`` then
``speaker,syllable,trial,train,index,recording_time_s,frame``.  ``time_s`` is
seconds since the production's consonant release (``--window vowel``: since
the previous vowel), ``time_norm`` the same divided by the span's duration.  Speaker, syllable and trial come from
file names like ``spk1_ta.tsv`` or ``spk1/ta_2.tsv`` (in other names, tokens such as
``OSN12`` and ``Kah``), the productions' labels, ``--labels TABLE``, or ``--speaker/--syllable``;
the command says which recordings' labels stay unknown.
``--productions-from TIER`` takes the productions from a label tier of each
recording (its ``NAME.TextGrid``, or MVIEW's words/phones) instead.
"""

from __future__ import annotations

import argparse
from pathlib import Path



def add_arguments(parser: argparse.ArgumentParser) -> None:
    from tonguevis.cli._common import (add_companion_arguments, add_productions_from_argument,
                                       add_reader_options_argument, add_run_arguments)

    parser.add_argument("paths", nargs="+", type=Path, metavar="PATH", help="recordings or folders of recordings")
    parser.add_argument("--sensors", metavar="MAP",
                        help="sensor map (JSON file or preset) for every recording; default: "
                             "sensor_map.json beside each recording if any")
    parser.add_argument("--csv", metavar="OUT", type=Path, required=True, help="long-format CSV of the curves")
    parser.add_argument("--png", metavar="OUT", type=Path, help="also plot the curves (absolute and normalised time)")
    parser.add_argument("--summary", metavar="OUT", type=Path,
                        help="also write per-group statistics (peak, time of peak, area) as CSV")
    parser.add_argument("--labels", metavar="TABLE", type=Path,
                        help="CSV with columns file,speaker,syllable[,trial] overriding the names")
    parser.add_argument("--speaker", metavar="NAME", help="the speaker of every recording (overrides the names)")
    parser.add_argument("--syllable", metavar="CV", help="the syllable of every recording, e.g. ka (overrides the "
                        "names; also tells the segmentation which articulator to follow)")
    parser.add_argument("--group-by", default="speaker,syllable",
                        help="grouping for the plot and summary, from speaker,syllable,trial,recording "
                             "(default: speaker,syllable)")
    parser.add_argument("--all", action="store_true", help="every production, not only the 2nd-4th of each train")
    parser.add_argument("--window", choices=("release", "vowel"), default="release",
                        help="curve span: release to next release (default), or previous vowel to own vowel "
                             "(the consonant mid-curve)")
    add_productions_from_argument(parser)
    # --labels is the name table above: each recording's TextGrid is the NAME.TextGrid beside it.
    add_reader_options_argument(parser, " of every recording")
    add_companion_arguments(parser, labels=False)
    add_run_arguments(parser, every=True)


def load_model(args):
    """The tongue model: ``mesh`` when given, else the shipped default."""
    from tonguevis.cli._common import load_model_args

    return load_model_args(args)


def run(args: argparse.Namespace) -> int:
    from tonguevis._progress import tqdm_progress
    from tonguevis.analysis.corpus import CorpusError, load_corpus, unknown_labels, with_labels
    from tonguevis.workflows.corpus import corpus_energy_curves
    from tonguevis.analysis.energy import GROUP_KEYS, summarize, write_curves_csv, write_summary_csv
    from tonguevis.cli._common import reading_options, run_settings_of
    from tonguevis.workflows.corpus import CurveSettings

    by = tuple(k.strip() for k in args.group_by.split(",") if k.strip())
    bad = [k for k in by if k not in GROUP_KEYS]
    if bad or not by:
        raise CorpusError(f"--group-by {args.group_by!r}: choose from {', '.join(GROUP_KEYS)}")
    corpus = with_labels(load_corpus(args.paths, table=args.labels), args.speaker, args.syllable)
    if not len(corpus):
        raise CorpusError(f"no recordings found in {', '.join(map(str, args.paths))}")
    if args.audio is not None and len(corpus) > 1:
        raise CorpusError(f"--audio names the sound of one recording, but {len(corpus)} were found; leave it out "
                          "and put each recording's WAV beside it under the same name (NAME.wav)")
    settings = run_settings_of(args)
    curves = CurveSettings(keep=None if args.all else (2, 3, 4), window=args.window, tier=args.productions_from)
    model = load_model(args)
    with tqdm_progress("energy curves", disable=args.quiet) as progress:
        result = corpus_energy_curves(corpus, settings, model, curves=curves, keep_motions=False, progress=progress,
                                      reading={"sensor_map": args.sensors, **reading_options(args)})
    for path, reason in result.skipped:
        print(f"skipped {path}: {reason}")
    for name, rest in result.rests.items():
        print(f"{name}: {rest.describe()}")
    options = {"speaker": "--speaker NAME", "syllable": "--syllable CV"}
    for name, which in unknown_labels(result.curves).items():
        print(f"{name}: {' and '.join(which)} unknown (not in the file name or the labels; give "
              f"{' '.join(options[w] for w in which)} or --labels TABLE)")
    write_curves_csv(result.curves, args.csv)
    print(f"{len(corpus)} recording(s), {len(result.curves)} production curves -> {args.csv}")
    summaries = summarize(result.curves, by) if result.curves else []
    for g in summaries:
        m, s = g.mean, g.std
        print(f"  {' '.join(map(str, g.key)):<16} n={g.n:<3} peak {1e3 * m['peak_J']:.3f} ± {1e3 * s['peak_J']:.3f} mJ "
              f"at {m['peak_time_norm']:.2f} ± {s['peak_time_norm']:.2f} (normalised), "
              f"area {1e3 * m['area_Js']:.4f} ± {1e3 * s['area_Js']:.4f} mJ·s")
    if args.summary is not None:
        write_summary_csv(summaries, by, args.summary)
        print(f"wrote {args.summary}")
    if args.png is not None:
        from tonguevis.render.energy import save_energy_png

        save_energy_png(result.curves, args.png, by, title="Elastic energy per production")
        print(f"wrote {args.png}")
    return 0
