"""``tonguevis batch CORPUS --out DIR``: every recording of a corpus, resumable, in parallel or on a Dask cluster.

Per recording (the same steps as ``simulate``, ``energy``, ``segment
--production K`` and ``validate``, with their defaults): the motion
(``motion.npz``), its energy curves and productions, the autoseeded
constraint-mode segmentation of each production (§5) and, with ``--steps
...,validate``, the leave-one-sensor-out validation; each written under
``DIR/recordings/`` as it finishes, then gathered into ``DIR/energy.parquet``
(the columns of ``tonguevis energy``), ``productions``, ``simulation``,
``segmentation`` and ``validation.parquet`` (``--csv``: CSV too).  A rerun
skips what is done with the same inputs and settings.  ``--jobs N`` runs N
worker processes here, ``--scheduler`` on a Dask cluster, ``--slurm`` on SLURM
jobs (dask-jobqueue; a recording in flight on a job that ends is listed as
lost, and the rerun does it).  A recording that fails
is listed in ``DIR/failures.csv`` and the others go on; the exit status is 1
when any failed or was lost, else 0.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from tonguevis.batch.settings import DEFAULT_STEPS, STEPS
    from tonguevis.cli._common import add_productions_from_argument, add_reader_options_argument, add_run_arguments

    parser.add_argument("paths", nargs="+", type=Path, metavar="CORPUS",
                        help="a folder of recordings (walked recursively) or recording files")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder (reused to resume)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--jobs", type=int, default=1, metavar="N",
                       help="worker processes on this machine (default 1: in this process)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on a Dask distributed cluster, e.g. tcp://10.0.0.5:8786 (DIR and the corpus "
                            "must be visible to its workers at the same paths)")
    where.add_argument("--slurm", action="store_true",
                       help="submit SLURM jobs of one-thread Dask workers (dask-jobqueue) and run there; this "
                            "process holds the scheduler: run it on a submit host, with DIR and the corpus on a "
                            "file system the nodes share")
    slurm = parser.add_argument_group("SLURM (with --slurm; the options override the profile's)")
    slurm.add_argument("--slurm-profile", type=Path, metavar="TOML",
                       help="a [slurm] table of jobs, cores, memory, walltime, queue, account, interface, "
                            "job_extra, prologue, python, local_directory (see the README)")
    slurm.add_argument("--slurm-jobs", type=int, metavar="N", help="SLURM jobs (default 1)")
    slurm.add_argument("--slurm-cores", type=int, metavar="N",
                       help="cores per job, one one-thread worker each (default 1)")
    slurm.add_argument("--slurm-memory", metavar="SIZE", help="memory per job, e.g. 8GB (default 2GB per core)")
    slurm.add_argument("--slurm-walltime", metavar="TIME", help="time limit per job, e.g. 02:00:00 (default 1 h)")
    slurm.add_argument("--slurm-queue", metavar="PARTITION", help="partition (default: the cluster's)")
    slurm.add_argument("--slurm-account", metavar="ACCOUNT", help="account to charge (default: yours)")
    parser.add_argument("--steps", default=",".join(DEFAULT_STEPS),
                        help=f"comma-separated steps from {','.join(STEPS)} (default {','.join(DEFAULT_STEPS)})")
    parser.add_argument("--csv", action="store_true", help="CSV beside every Parquet table")
    parser.add_argument("--sensors", metavar="MAP",
                        help="sensor map (JSON file or preset) for every recording; default: "
                             "sensor_map.json beside each recording if any")
    parser.add_argument("--labels", metavar="TABLE", type=Path,
                        help="CSV with columns file,speaker,syllable[,trial] overriding the names")
    parser.add_argument("--all", action="store_true", help="every production, not only the 2nd-4th of each train")
    parser.add_argument("--window", choices=("release", "vowel"), default="release",
                        help="energy curve span, as tonguevis energy --window (default: release)")
    add_productions_from_argument(parser)
    parser.add_argument("--measures-palate", metavar="P",
                        help="the palate of the measures step (as tonguevis measures --palate: a palate file, "
                             "'generic' or 'none'); default: --palate's file when given, else 'generic'")
    parser.add_argument("--group-by", default="speaker,syllable",
                        help="the labels the measures step pools repetitions by for the STI and the averages, from "
                             "speaker,syllable,trial,recording,train,index (default: speaker,syllable)")
    parser.add_argument("--segment-first", type=int, metavar="N",
                        help="segment only the first N productions of each recording (default: every one; "
                             "segmentation takes several seconds per production)")
    parser.add_argument("--no-static", action="store_true", help="validation without the quasi-static baseline")
    parser.add_argument("--force", action="store_true", help="redo every step, even those up to date")
    add_reader_options_argument(parser, " of every recording")
    add_run_arguments(parser, every=True)


def load_model(args):
    """The tongue model given in Python (None: the settings' ``--mesh``, read by each worker, else the shipped
    tongue).  A hook the tests replace."""
    return None


def measures_palate(args: argparse.Namespace):
    """The measures step's palate: ``--measures-palate`` (None for 'none'), else ``--palate``'s file, else "generic"."""
    import os

    chosen = args.measures_palate
    if chosen is None:
        given = getattr(args, "palate", None)
        return "generic" if given in (None, "generic") else os.path.abspath(given)
    return None if chosen == "none" else chosen if chosen == "generic" else os.path.abspath(chosen)


SLURM_OPTIONS = ("jobs", "cores", "memory", "walltime", "queue", "account")


def slurm_options(args: argparse.Namespace):
    """The :class:`~tonguevis.batch.slurm.SlurmOptions` of ``--slurm`` (profile, then options), or None."""
    given = {name: getattr(args, f"slurm_{name}") for name in SLURM_OPTIONS}
    if not args.slurm:
        named = [f"--slurm-{n}" for n, v in given.items() if v is not None] + (
            ["--slurm-profile"] if args.slurm_profile is not None else [])
        if named:
            from tonguevis.batch import BatchError

            raise BatchError(f"{', '.join(named)} without --slurm")
        return None
    from tonguevis.batch.api import require

    require("distributed", "dask_jobqueue")
    from tonguevis.batch.slurm import SlurmOptions

    if args.slurm_profile is not None:
        return SlurmOptions.from_profile(args.slurm_profile, **given)
    return SlurmOptions(**{k: v for k, v in given.items() if v is not None})


def run(args: argparse.Namespace) -> int:
    from tonguevis._progress import tqdm_progress
    from tonguevis.batch import BatchSettings, run as run_batch
    import dataclasses
    import os

    from tonguevis.cli._common import parse_options, run_settings_of

    # How each recording is simulated comes from the options every simulating command shares (so the
    # batch simulates what `tonguevis simulate` and `segment` do with the same options); the mesh and the palate
    # go to the workers as their files (read by each worker; the palate checked here first).
    run_settings = run_settings_of(args)
    if args.palate not in (None, "generic"):
        run_settings = run_settings.replace(palate=os.path.abspath(args.palate))
    settings = BatchSettings(
        **{name: getattr(run_settings, name) for name in run_settings.names()},
        steps=args.steps, sensor_map=args.sensors, labels=args.labels,
        read_options=parse_options(args.option), keep=None if args.all else (2, 3, 4), window=args.window,
        tier=args.productions_from, segment_first=args.segment_first, quasi_static=not args.no_static, csv=args.csv,
        measures_palate=measures_palate(args), group_by=args.group_by)
    model = load_model(args)
    slurm = slurm_options(args)
    if slurm is not None and not args.quiet:
        slurm = dataclasses.replace(slurm, notify=_say)
    client = None
    if args.scheduler is not None:
        from tonguevis.batch.api import require

        require("distributed")
        from distributed import Client

        client = Client(args.scheduler)
    try:
        with tqdm_progress("batch", disable=args.quiet, unit="recording") as progress:
            result = run_batch(args.paths, args.out, workers=slurm or client or args.jobs, model=model,
                               settings=settings, force=args.force, progress=progress)
    except KeyboardInterrupt:
        print(f"the recordings finished are kept in {args.out}: run the same command again to resume",
              file=sys.stderr)
        raise
    finally:
        if client is not None:
            client.close()
    lost: dict[str, list[str]] = {}
    for file, step, error in result.failures:
        if step == "lost":
            lost.setdefault(error, []).append(file)
        else:
            print(f"failed: {file} ({step}): {error}")
    for error, files in lost.items():  # those not started share one reason: one line (failures.csv has each)
        named = files[0] if len(files) == 1 else f"{len(files)} recordings ({', '.join(files[:3])}" + (
            ", ...)" if len(files) > 3 else ")")
        print(f"lost: {named}: {error}")
    print(result.summary())
    return 0 if result.ok else 1


def _say(line: str) -> None:
    """A line above the progress bar (the SLURM jobs' starts and ends)."""
    from tqdm import tqdm

    tqdm.write(f"batch: {line}", file=sys.stderr)
