"""``run(paths, out, workers=...)``: a whole corpus, resumable, on this machine or a Dask cluster."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable

from tonguevis._progress import ProgressCallback, report
from tonguevis.batch import store
from tonguevis.batch.settings import BatchError, BatchSettings, ModelSpec, input_digest, model_key, step_keys

from tonguevis._logging import logger, verbose


@dataclass
class BatchResult:
    """What :func:`run` did.

    out : the output folder.  files : the corpus (paths relative to its folder).
    done : recordings processed in this run without failure.  up_to_date :
    recordings with nothing to redo.  failures : (file, step, error) of every
    recording that failed (also in ``out/failures.csv``).  tables : name ->
    path of the corpus tables written.  seconds : wall time, and ``timings``
    its parts: "model" (building it in this process), "plan" (walking the
    corpus, hashing the inputs, reading the manifests), "prepare"
    (modal basis and warp kernels, before any worker starts), "run" (the
    recordings) and "gather" (the corpus tables).  workers : pid -> largest
    resident memory (MiB) of each process that ran recordings.  cpu_seconds :
    CPU time the recordings took in their workers' threads.
    """

    out: Path
    files: list[str]
    done: list[str] = field(default_factory=list)
    up_to_date: list[str] = field(default_factory=list)
    failures: list[tuple[str, str, str]] = field(default_factory=list)
    tables: dict[str, Path] = field(default_factory=dict)
    seconds: float = 0.0
    workers: dict[int, float] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    cpu_seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.failures

    @property
    def lost(self) -> list[str]:
        """Recordings not done because their worker went away (a SLURM job ended): a rerun does them."""
        return [file for file, step, _ in self.failures if step == "lost"]

    def summary(self) -> str:
        """One line: counts, time, where the results are."""
        n = len(self.files)
        parts = [f"{len(self.done)} done"]
        if self.up_to_date:
            parts.append(f"{len(self.up_to_date)} up to date")
        failed = len(self.failures) - len(self.lost)
        parts.append(f"{failed} failed" + (f" (see {self.out / store.FAILURES})" if failed else ""))
        if self.lost:
            parts.append(f"{len(self.lost)} lost with their SLURM job (run the same command again to resume)")
        return (f"batch: {n} recording{'s' if n != 1 else ''} in {self.seconds:.1f} s: {', '.join(parts)}; "
                f"tables in {self.out}")


def _counts(done: int, failed: int, fresh: int, total: int, lost: int = 0) -> str:
    return (f"{done} done, {failed - lost} failed, " + (f"{lost} lost, " if lost else "")
            + f"{total - done - failed - fresh} remaining" + (f" ({fresh} up to date)" if fresh else ""))


@verbose
def run(paths: str | os.PathLike | Iterable[str | os.PathLike], out: str | os.PathLike, *, workers=1,
        model=None, settings: BatchSettings | None = None, force: bool = False,
        progress: ProgressCallback | None = None, **options) -> BatchResult:
    """Process every recording of ``paths`` (files, or folders walked recursively) into ``out``.

    workers : where the recordings run: a number of worker processes on this machine (1: in this process), a
        ``distributed.Client`` (its Dask cluster), or a :class:`tonguevis.batch.slurm.SlurmOptions` (SLURM
        jobs of Dask workers submitted for this batch; their logs go to ``out/slurm/``, their ids to the
        manifests and batch.json; a recording in flight on a job that ends is lost: ``failures`` with step
        "lost", the rest go on; its ``notify`` hears of each job's events).
    model : a TongueModel; default the settings' ``mesh`` (a file, with ``mesh_axes``) read by each worker,
        else the shipped tongue.
    settings / options : :class:`BatchSettings`, or its fields as keywords
        (``steps="simulate,energy"``, ``modes=40``, ``csv=True``, ``labels="labels.csv"``...).
    force : redo every step even where the results are up to date.
    progress : ``progress(finished, total, "3 done, 1 failed, 6 remaining")`` after every recording.

    Per-recording results are written as each finishes; a failing recording is
    recorded (``out/failures.csv``) and the others go on; then the corpus tables
    are gathered.  Interrupting loses only the recordings in flight: a rerun
    with the same inputs and settings skips what is done (content hashes, see
    :mod:`tonguevis.batch.settings`).
    """
    from tonguevis.analysis.corpus import find_recordings, load_corpus

    started = time.perf_counter()
    jobs, client, slurm = _workers(workers)
    require("pyarrow", *(["distributed"] if client is not None else ["distributed", "dask_jobqueue"]
                         if slurm is not None else ["joblib"] if jobs > 1 else []))
    settings = replace(settings or BatchSettings(), **options) if options else (settings or BatchSettings())
    labels = settings.labels
    paths = [Path(paths)] if isinstance(paths, (str, os.PathLike)) else [Path(p) for p in paths]
    out = Path(out)
    out_abs = Path(os.path.abspath(out))
    files = find_recordings(paths)
    excluded = {Path(os.path.abspath(labels))} if labels is not None else set()
    files = [f for f in files if out_abs not in Path(os.path.abspath(f)).parents
             and Path(os.path.abspath(f)) not in excluded]
    if not files:
        raise BatchError(f"no recordings found in {', '.join(map(str, paths))}")
    corpus = load_corpus(files, table=labels)
    root, names = store.relative_files([e.path for e in corpus], paths)
    out.mkdir(parents=True, exist_ok=True)
    store.clean_temporary(out_abs)
    folders = store.output_folders(names, out_abs)

    t0 = time.perf_counter()
    spec = ModelSpec.of(model, settings.mesh, settings.mesh_axes)
    built = model if model is not None else spec.build()
    spec.key = model_key(built)
    keys = []
    tasks = []
    result = BatchResult(out, names)
    result.timings["model"] = time.perf_counter() - t0
    from tonguevis.batch.tasks import Task

    for entry, name, folder in zip(corpus, names, folders):
        table_labels = {"speaker": entry.speaker, "syllable": entry.syllable, "trial": entry.trial,
                        "source": entry.source}
        try:
            digest = input_digest(entry.path, settings.sensor_map, table_labels)
        except OSError as exc:
            digest = f"unreadable: {exc}"
        k = step_keys(digest, spec.key, settings)
        keys.append(k)
        todo = settings.steps if force else store.steps_to_do(folder, k, settings.steps, settings.csv)
        if todo:
            tasks.append(Task(Path(os.path.abspath(entry.path)), name, folder, entry, k, todo, settings))
        else:
            result.up_to_date.append(name)

    result.timings["plan"] = time.perf_counter() - started - result.timings["model"]
    failed: dict[str, tuple[str, str]] = {}
    total = len(names)
    slurm_jobs: dict = {}
    lost = [0]  # of the failures, the recordings lost with their worker

    def on_done(outcome) -> None:
        if outcome.failure:
            failed[outcome.file] = outcome.failure
            lost[0] += outcome.failure[0] == "lost"
            logger.info("%s failed at %s: %s", outcome.file, *outcome.failure)
        else:
            result.done.append(outcome.file)
        result.workers[outcome.pid] = max(result.workers.get(outcome.pid, 0.0), outcome.max_rss_mb)
        result.cpu_seconds += outcome.cpu_seconds
        finished = len(result.done) + len(failed) + len(result.up_to_date)
        report(progress, finished, total,
               _counts(len(result.done), len(failed), len(result.up_to_date), total, lost[0]))

    report(progress, len(result.up_to_date), total, _counts(0, 0, len(result.up_to_date), total))
    simulating = any(step != "measures" for task in tasks for step in task.todo)  # the measures need no modes
    result.timings["prepare"] = _prepare(built, settings) if simulating else 0.0
    t0 = time.perf_counter()
    if tasks:
        from tonguevis.batch import runners, tasks as task_module

        if slurm is not None:
            from tonguevis.batch.slurm import slurm_cluster

            with slurm_cluster(slurm, out_abs / store.SLURM_LOGS) as watch:
                runners.run_dask(tasks, spec, watch.client, on_done, watch)
                slurm_jobs = watch.record()
        elif client is not None:
            runners.run_dask(tasks, spec, client, on_done)
        elif jobs == 1:
            task_module.remember_model(spec, built)
            runners.run_here(tasks, spec, on_done)
        else:
            runners.run_loky(tasks, spec, jobs, on_done)
    result.timings["run"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    result.tables = store.gather(out_abs, folders, keys, settings.steps, settings.csv)
    if "measures" in settings.steps:
        result.tables.update(store.gather_repetitions(out_abs, settings.group_by, settings.csv))
    result.timings["gather"] = time.perf_counter() - t0
    result.failures = [(name, *failed[name]) for name in names if name in failed]
    store.write_failures(out_abs, result.failures)
    result.seconds = time.perf_counter() - started
    from tonguevis import __version__

    store.write_settings(out_abs, {
        "tonguevis": __version__, "corpus": str(root), "recordings": len(names), "settings": settings.as_dict(),
        "model": {"kind": spec.kind, "mesh": str(spec.mesh) if spec.kind == "file" else None, "key": spec.key},
        "runner": _runner(jobs, client, slurm),
        **({"slurm": {"options": slurm.as_dict(), **slurm_jobs, "logs": str(out_abs / store.SLURM_LOGS)}}
           if slurm is not None else {}),
        "last_run": {"done": len(result.done), "up_to_date": len(result.up_to_date),
                     "failed": len(result.failures), "seconds": result.seconds},
    })
    return result


def _workers(workers) -> tuple[int, object, object]:
    """(processes here, Dask client or None, SLURM options or None) of :func:`run`'s ``workers``."""
    from numbers import Integral

    if isinstance(workers, bool) or workers is None:
        raise BatchError(f"workers must be a number of processes, a Dask client or SLURM options, got {workers!r}")
    if isinstance(workers, Integral):
        if workers < 1:
            raise BatchError(f"workers must be at least 1, got {workers}")
        return int(workers), None, None
    if type(workers).__name__ == "SlurmOptions":
        return 1, None, workers
    if hasattr(workers, "submit") and hasattr(workers, "scheduler_info"):  # a distributed.Client
        return 1, workers, None
    raise BatchError(f"workers must be a number of processes, a Dask client or SLURM options, got {workers!r}")


def _runner(jobs: int, client, slurm) -> str:
    if slurm is not None:
        return f"slurm, {slurm.jobs} job{'s' if slurm.jobs != 1 else ''} of {slurm.cores} one-thread worker(s)"
    return "dask" if client is not None else ("here" if jobs == 1 else f"loky, {jobs} workers")


def require(*modules: str) -> None:
    """BatchError naming the ``batch`` extra when one of ``modules`` is not installed."""
    import importlib.util

    missing = [m for m in modules if importlib.util.find_spec(m) is None]
    if missing:
        raise BatchError(f"the batch needs {', '.join(missing)}: pip install 'tonguevis[batch]'")


def _prepare(model, settings: BatchSettings) -> float:
    """The modal basis on disk and the warp kernels compiled, once, before any worker starts; returns seconds."""
    from tonguevis._backend import prepare_kernels

    started = time.perf_counter()
    model.basis(settings.modes)
    prepare_kernels()
    return time.perf_counter() - started
