"""One recording's work, run in a worker: :func:`process` (open, then each step asked, results written as they finish).

Every step goes through the same functions as the single-file commands:
:func:`tonguevis.workflows.corpus.open_entry` and
:func:`~tonguevis.workflows.simulate_recording` (``tonguevis simulate``),
:func:`~tonguevis.workflows.corpus.entry_curves` (``tonguevis energy``),
:func:`~tonguevis.analysis.segmentation.production_target` and
:func:`~tonguevis.analysis.segmentation.segment` with the §5 defaults
(``tonguevis segment --production K``),
:func:`~tonguevis.analysis.validation.validate` (``tonguevis validate``) and
:func:`~tonguevis.workflows.measures.measure_recording` (``tonguevis measures``).
A failing step is recorded in the recording's manifest with its message; the
worker then moves on to the next recording.
"""

from __future__ import annotations

import logging
import os
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tonguevis.analysis.corpus import CorpusEntry
from tonguevis.batch import store, tables
from tonguevis.batch.settings import BatchSettings, ModelSpec
from tonguevis.errors import Cancelled, TonguevisError

from tonguevis._logging import logger

_models: dict[str, object] = {}
_models_lock = threading.Lock()


@dataclass
class Task:
    """What a worker needs for one recording.

    path : the recording (absolute); file : its path relative to the corpus
    folder (how tables and failures.csv name it); folder : its output folder;
    entry : its corpus labels; keys : step -> content hash; todo : the steps to
    run now (the others are up to date); settings : of every step.
    """

    path: Path
    file: str
    folder: Path
    entry: CorpusEntry
    keys: dict[str, str]
    todo: tuple[str, ...]
    settings: BatchSettings


@dataclass
class Outcome:
    """What a worker reports back: the steps done now, the failure (step, message) if any, wall and CPU
    seconds (of the worker's thread), the worker's process id and its largest resident memory (MiB),
    and the SLURM job the worker ran in (None outside SLURM)."""

    file: str
    done: tuple[str, ...] = ()
    failure: tuple[str, str] | None = None
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    pid: int = field(default_factory=os.getpid)
    max_rss_mb: float = 0.0
    slurm_job: str | None = field(default_factory=lambda: os.environ.get("SLURM_JOB_ID"))


def remember_model(spec: ModelSpec, model) -> None:
    """Let this process reuse ``model`` for ``spec`` (the parent's, for in-process runs)."""
    with _models_lock:
        _models[spec.key] = model


def model_for(spec: ModelSpec):
    """The model of ``spec``, built once per process (its modal basis and operators stay cached on it)."""
    with _models_lock:
        model = _models.get(spec.key)
        if model is None:
            model = _models[spec.key] = spec.build()
        return model


class _Collect(logging.Handler):
    """The package's warnings of one thread (a recording's notes go to its manifest, not the terminal of a worker)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.thread = threading.get_ident()
        self.messages: list[str] = []

    def emit(self, record):
        if record.thread == self.thread:
            self.messages.append(record.getMessage())


def _max_rss_mb() -> float:
    """This process's largest resident memory so far, MiB (VmHWM: unlike ru_maxrss, not inherited
    from the parent a worker was forked from)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0  # kB
    except OSError:
        pass
    try:
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux
    except (ImportError, OSError):  # pragma: no cover - neither Linux nor Unix
        return float("nan")


def process(task: Task, spec: ModelSpec) -> Outcome:
    """Run ``task.todo`` for one recording; never raises for a bad recording (see :class:`Outcome`)."""
    from tonguevis._blas import single_threaded_blas

    started, cpu = time.perf_counter(), time.thread_time()
    collect = _Collect()
    logger.addHandler(collect)
    manifest = store.read_manifest(task.folder) or {}
    manifest.update({"file": task.file, "recording": task.entry.name, "failure": None,
                     "slurm_job": os.environ.get("SLURM_JOB_ID")})  # the job that ran it, if SLURM's
    steps = manifest.setdefault("steps", {})
    for step in task.todo:
        steps.pop(step, None)  # its old results no longer count
    done: list[str] = []
    step = "open"
    try:
        with single_threaded_blas():
            task.folder.mkdir(parents=True, exist_ok=True)
            model = model_for(spec)
            from tonguevis.workflows.corpus import open_entry

            entry, rec = open_entry(task.entry, task.settings.sensor_map, dict(task.settings.read_options))
            motion = None
            for step in task.todo:
                t0 = time.perf_counter()
                if step in ("simulate", "energy", "segment") and motion is None:
                    motion = _motion(task, manifest, rec, model, save=step == "simulate")
                outputs = _STEPS[step](task, entry, rec, model, motion, time.perf_counter() - t0)
                steps[step] = {"key": task.keys[step], "seconds": time.perf_counter() - t0, "outputs": outputs}
                done.append(step)
                store.write_manifest(task.folder, manifest)
    except (Cancelled, KeyboardInterrupt):
        raise
    except Exception as exc:  # noqa: BLE001 - a bad recording must not stop the corpus
        message = str(exc) if isinstance(exc, TonguevisError) else f"{type(exc).__name__}: {exc}"
        message = " ".join(message.split()) or type(exc).__name__
        manifest["failure"] = {"step": step, "error": message, "traceback": traceback.format_exc()}
    finally:
        logger.removeHandler(collect)
    manifest["warnings"] = collect.messages
    if task.folder.is_dir():
        store.write_manifest(task.folder, manifest)
    failure = manifest["failure"]
    return Outcome(task.file, tuple(done), (failure["step"], failure["error"]) if failure else None,
                   time.perf_counter() - started, time.thread_time() - cpu, os.getpid(), _max_rss_mb())


def _motion(task: Task, manifest: dict, rec, model, save: bool):
    """The recording's motion: simulated (and saved when the simulate step runs), or the saved one when current."""
    from tonguevis.sim.motion import Motion
    from tonguevis.workflows import simulate_recording

    path = task.folder / store.MOTION
    if not save and store.step_current(manifest, "simulate", task.keys["simulate"], task.folder):
        from tonguevis.sim.placement import PlacedModel, placed_model_of

        motion = Motion.load(path)
        if getattr(motion.model, "base_model", None) is not None:
            return motion  # with sensor patches: its own model, the modes and the patches (Motion.load rebuilt it)
        placed = placed_model_of(motion.model)
        # the same model (the key says so), with its caches; placed in the speaker as the saved one was
        motion.model = model if placed is None else PlacedModel(model, placed.placement, placed.keep_frequencies)
        return motion
    motion = simulate_recording(rec, model, task.settings.run_settings())
    if save:
        motion.save(path)
    return motion


def _simulate(task, entry, rec, model, motion, seconds):
    row = tables.simulation_row(entry, task.file, rec, motion, seconds)
    written = tables.write(tables.to_arrow("simulation", [row]), task.folder / "simulation.parquet",
                           task.settings.csv)
    return [store.MOTION] + [p.name for p in written]


def _energy(task, entry, rec, model, motion, seconds):
    from tonguevis.workflows.corpus import entry_curves
    from tonguevis.analysis.energy import write_curves_csv

    s = task.settings
    curves, table = entry_curves(entry, rec, motion, keep=s.keep, window=s.window, tier=s.tier)
    written = tables.write(tables.energy_table(curves), task.folder / "energy.parquet")
    if s.csv:  # the very format of ``tonguevis energy --csv``
        write_curves_csv(curves, task.folder / "energy.csv")
        written.append(task.folder / "energy.csv")
    rows = tables.production_rows(entry, task.file, table, curves, s.window)
    written += tables.write(tables.to_arrow("productions", rows), task.folder / "productions.parquet", s.csv)
    return [p.name for p in written]


def _segment(task, entry, rec, model, motion, seconds):
    from tonguevis._files import atomic_write
    from tonguevis.analysis.segmentation import production_target, segment
    from tonguevis.workflows import find_recording_productions

    s = task.settings
    productions = list(find_recording_productions(rec, keep=s.keep, tier=s.tier))
    if s.segment_first is not None:
        productions = productions[:s.segment_first]
    rows, labels, which = [], [], []
    for number, production in enumerate(productions, start=1):
        # one thread: the workers already use the cores (and threaded SuperLU solves keep memory)
        result = segment(motion.model, production_target(motion, production), "constraint", threads=1)
        rows += tables.segmentation_rows(entry, task.file, number, production, result)
        labels.append(result.labels.astype(np.int32))
        which.append((number, production.train, production.index))
    written = tables.write(tables.to_arrow("segmentation", rows), task.folder / "segmentation.parquet", s.csv)

    def save(tmp):
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, labels=np.array(labels, dtype=np.int32).reshape(len(labels), -1),
                                productions=np.array(which, dtype=np.int64).reshape(-1, 3))

    atomic_write(task.folder / store.SEGMENT_LABELS, save)
    return [p.name for p in written] + [store.SEGMENT_LABELS]


def _validate(task, entry, rec, model, motion, seconds):
    from tonguevis.analysis.validation import validate

    s = task.settings
    result = validate(rec, s.run_settings(), model, quasi_static=s.quasi_static)
    result.write_json(task.folder / "validation.json")
    rows = tables.validation_rows(entry, task.file, result.as_dict())
    written = tables.write(tables.to_arrow("validation", rows), task.folder / "validation.parquet", s.csv)
    return ["validation.json"] + [p.name for p in written]


def _measures(task, entry, rec, model, motion, seconds):
    """``tonguevis measures`` of the recording (no simulation): its table and its productions' records."""
    from tonguevis.workflows.measures import measure_recording

    s = task.settings
    result = measure_recording(rec, s.measures_palate, tier=s.tier, keep=s.keep)
    rows = tables.measures_rows(entry, task.file, result.rows)
    written = tables.write(tables.to_arrow("measures", rows), task.folder / "measures.parquet", s.csv)
    written += tables.write(tables.trajectories_table(entry, task.file, result.table, result.repetitions),
                            task.folder / "trajectories.parquet", s.csv)
    return [p.name for p in written]


_STEPS = {"simulate": _simulate, "energy": _energy, "segment": _segment, "validate": _validate,
          "measures": _measures}
