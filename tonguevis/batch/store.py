"""The output folder of a batch: where each recording's results go, what is up to date, the gathered tables.

Layout of ``DIR``::

    recordings/<path of the recording in the corpus, without extension>/
        manifest.json       per step: its key (content hash), seconds, the files it wrote; the failure if any
        motion.npz          (simulate) the motion, Motion.save
        simulation.parquet  energy.parquet  productions.parquet  segmentation.parquet (+ segmentation.npz: labels)
        validation.parquet (+ validation.json, as tonguevis validate --json)      [+ .csv of each with --csv]
        measures.parquet  trajectories.parquet (measures: tonguevis measures, no simulation)
    simulation.parquet  energy.parquet  productions.parquet  segmentation.parquet  validation.parquet  [+ .csv]
    measures.parquet  trajectories.parquet  repetitions.parquet  averages.parquet (STI and means per group)
    failures.csv        file, step, error (step "lost": its SLURM job ended while it ran; a rerun does it)
    batch.json          the settings, the model's key, the counts of the last run (with --slurm: its jobs)
    slurm/              with --slurm: the jobs' logs (tonguevis-batch-JOBID.out/.err)

A step counts as done when the manifest holds it with the current key and its
files exist; every file is written to a temporary name and renamed, and the
manifest last, so an interrupted run leaves no half-written result behind.
"""

from __future__ import annotations

import csv
import json
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Iterable

from tonguevis._files import atomic_write, atomic_write_text
from tonguevis.batch.tables import STEP_TABLES

RECORDINGS = "recordings"
MANIFEST = "manifest.json"
MOTION = "motion.npz"
SEGMENT_LABELS = "segmentation.npz"
FAILURES = "failures.csv"
SETTINGS = "batch.json"
SLURM_LOGS = "slurm"
#: Threads reading the recordings' tables while gathering (the reads are small and mostly wait).
READERS = 4


def output_folders(files: list[str], out: Path) -> list[Path]:
    """Each recording's output folder: its corpus path without extension (with it when two would collide)."""
    plain = [Path(f).with_suffix("") for f in files]
    seen: dict[Path, int] = {}
    for p in plain:
        seen[p] = seen.get(p, 0) + 1
    return [out / RECORDINGS / (p if seen[p] == 1 else Path(f).parent / Path(f).name.replace(".", "_"))
            for p, f in zip(plain, files)]


def read_manifest(folder: Path) -> dict | None:
    try:
        return json.loads((Path(folder) / MANIFEST).read_text())
    except (OSError, ValueError):
        return None


def write_manifest(folder: Path, manifest: dict) -> None:
    atomic_write_text(Path(folder) / MANIFEST, json.dumps(manifest, indent=1, default=str) + "\n")


def step_current(manifest: dict | None, step: str, key: str, folder: Path, csv_too: bool = False) -> bool:
    """Whether ``step``'s results in ``folder`` are those of ``key`` and all there (with CSV when asked)."""
    entry = (manifest or {}).get("steps", {}).get(step)
    if not entry or entry.get("key") != key:
        return False
    outputs = entry.get("outputs", [])
    if csv_too and any(f"{t}.csv" not in outputs for t in STEP_TABLES[step]):
        return False
    return all((folder / name).is_file() for name in outputs)


def clean_temporary(folder: Path) -> int:
    """Remove the temporary files a killed run left in ``folder`` (``atomic_write``'s ``.NAME.*.tmp*``); returns how many.

    Only the task of a recording writes in its folder, and only the client in ``DIR``: when they
    are not running, such a file is a leftover.
    """
    removed = 0
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return 0
    for entry in entries:
        if entry.name.startswith(".") and ".tmp" in entry.name and entry.is_file():
            try:
                os.unlink(entry.path)
                removed += 1
            except OSError:
                pass
    return removed


def steps_to_do(folder: Path, keys: dict[str, str], steps: Iterable[str], csv_too: bool) -> tuple[str, ...]:
    """The steps of ``steps`` whose results in ``folder`` are missing or out of date (and its leftovers removed)."""
    clean_temporary(folder)
    manifest = read_manifest(folder)
    return tuple(s for s in steps if not step_current(manifest, s, keys[s], folder, csv_too))


def gather(out: Path, folders: list[Path], keys: list[dict], steps: Iterable[str], csv: bool) -> dict[str, Path]:
    """Write the corpus tables of ``steps`` from the recordings' current results, in corpus order.

    Streams one recording at a time (memory does not grow with the corpus);
    CSV (with ``csv``) is the recordings' CSV files one after the other, one header.
    """
    import pyarrow.parquet as pq

    from tonguevis.batch import tables

    written = {}
    manifests = [read_manifest(f) for f in folders]
    for step in steps:
        current = [f for f, m, k in zip(folders, manifests, keys) if step_current(m, step, k[step], f)]
        for name in STEP_TABLES[step]:
            parts = [f / f"{name}.parquet" for f in current if (f / f"{name}.parquet").is_file()]
            path = out / f"{name}.parquet"

            def write_parquet(tmp, parts=parts, name=name):
                schema = tables.schema(name)
                with pq.ParquetWriter(tmp, schema) as writer, ThreadPoolExecutor(READERS) as pool:
                    for start in range(0, len(parts), 64):  # read ahead a little, in threads, keep the order
                        for table in pool.map(lambda part: pq.read_table(part, schema=schema),
                                              parts[start:start + 64]):
                            writer.write_table(table)

            atomic_write(path, write_parquet)
            written[name] = path
            if csv:
                _concat_csv([p.with_suffix(".csv") for p in parts], out / f"{name}.csv", tables.columns(name))
                written[f"{name}.csv"] = out / f"{name}.csv"
    return written


def gather_repetitions(out: Path, by, csv: bool) -> dict[str, Path]:
    """``repetitions`` and ``averages`` of the corpus, pooled by the labels ``by``, from its gathered
    ``trajectories.parquet`` (none when there is none)."""
    import pyarrow.parquet as pq

    from tonguevis.batch import tables

    source = out / "trajectories.parquet"
    if not source.is_file():
        return {}
    written = {}
    for name, table in zip(("repetitions", "averages"), tables.repetition_tables(pq.read_table(source), by)):
        for path in tables.write(table, out / f"{name}.parquet", csv):
            written[path.name if path.suffix == ".csv" else name] = path
    return written


def _concat_csv(parts: list[Path], path: Path, columns: list[str]) -> None:
    def write(tmp):
        with open(tmp, "w", newline="") as out:
            header = False
            for part in parts:
                if not part.is_file():
                    continue
                with open(part, newline="") as fh:
                    first = fh.readline()
                    if not header:
                        out.write(first)
                        header = True
                    for chunk in iter(lambda: fh.read(1 << 20), ""):
                        out.write(chunk)
            if not header:
                csv.writer(out).writerow(columns)

    atomic_write(path, write)


def write_failures(out: Path, rows: list[tuple[str, str, str]]) -> Path:
    path = out / FAILURES

    def write(tmp):
        with open(tmp, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(["file", "step", "error"])
            writer.writerows(rows)

    atomic_write(path, write)
    return path


def write_settings(out: Path, document: dict) -> None:
    atomic_write_text(out / SETTINGS, json.dumps(document, indent=1, default=str) + "\n")


def relative_files(files: list[Path], paths: list[Path]) -> tuple[Path, list[str]]:
    """(corpus folder, each file's path relative to it as POSIX text).

    The corpus folder is the one folder given, else the deepest folder holding every file.
    """
    absolute = [Path(os.path.abspath(f)) for f in files]
    if len(paths) == 1 and Path(paths[0]).is_dir():
        root = Path(os.path.abspath(paths[0]))
    else:
        root = Path(os.path.commonpath([str(f.parent) for f in absolute])) if absolute else Path.cwd()
    return root, [f.relative_to(root).as_posix() for f in absolute]
