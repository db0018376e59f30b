"""A whole corpus at once: simulate, energy curves, segmentation and validation of every recording.

``run(paths, out, workers=...)`` (processes, a Dask client or SLURM options) (and ``tonguevis batch``) runs the
single-file pipeline on every recording, on this machine (joblib/loky worker
processes), on a Dask distributed cluster or on SLURM jobs, writes each recording's results
as it finishes, skips what an earlier run already did with the same inputs and
settings, records failures without stopping, and gathers corpus tables
(Parquet, optionally CSV) that R and pandas open directly.

* :mod:`~tonguevis.batch.settings`: steps, settings, the model a worker builds, content hashes.
* :mod:`~tonguevis.batch.tasks`: one recording's work in a worker.
* :mod:`~tonguevis.batch.tables`: the tables' schemas and rows.
* :mod:`~tonguevis.batch.store`: the output folder, what is up to date, gathering.
* :mod:`~tonguevis.batch.runners`: in process, loky, Dask.
* :mod:`~tonguevis.batch.slurm`: SLURM jobs of Dask workers (dask-jobqueue), their options and profile;
  :mod:`~tonguevis.batch.slurm_jobs` follows the jobs as they run.
"""

from __future__ import annotations

from tonguevis.batch.settings import DEFAULT_STEPS, STEPS, BatchError, BatchSettings, parse_steps

__all__ = ["BatchError", "BatchResult", "BatchSettings", "DEFAULT_STEPS", "STEPS", "parse_steps", "run"]


def __getattr__(name: str):  # the runner and its imports load when first used
    if name in ("run", "BatchResult"):
        from tonguevis.batch import api

        return getattr(api, name)
    raise AttributeError(f"module 'tonguevis.batch' has no attribute {name!r}")
