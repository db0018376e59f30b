"""The batch on a SLURM cluster: dask-jobqueue submits one-thread Dask workers as SLURM jobs.

:class:`SlurmOptions` says what to ask SLURM for (``--slurm-jobs``, ``--slurm-cores`` ...,
or a lab's TOML profile); :func:`slurm_cluster` submits the jobs and yields a
:class:`~tonguevis.batch.slurm_jobs.JobWatch` (with its Dask client), which
:func:`tonguevis.batch.runners.run_dask` polls.  The
scheduler runs in this process; the workers reach it, and read the corpus and write
``--out``, at the same paths: a shared file system.

A job that ends (``scancel``, its walltime) takes the recordings in flight on its workers
with it: they are reported lost, not retried (a recording that exceeded the job's memory
would take the next job down too), and the rerun of the same command does them.  Each
worker holds one recording at a time, so nothing waits queued on a worker that dies.
When every job has ended, the recordings not started are reported lost as well.
"""

from __future__ import annotations

import logging
import os
import re
import subprocess
import tempfile
import time
import tomllib
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Iterator

from tonguevis.batch.settings import BatchError
from tonguevis.batch.slurm_jobs import JOB_NAME, JobWatch, Notify, slurm_version

from tonguevis._logging import library_quieted, logger

_WALLTIME = re.compile(r"^(\d+-)?\d+(:\d{1,2}){0,2}$")  # SLURM's forms: M, M:S, H:M:S, D-H, D-H:M, D-H:M:S


@dataclass(frozen=True)
class SlurmOptions:
    """What each SLURM job asks for, and how many.

    jobs : SLURM jobs submitted.  cores : CPU cores per job, each running one
    one-thread worker process.  memory : per job (``"8GB"``; default 2 GB per
    core: a worker took 0.55-0.7 GB on the shipped tongue; Dask restarts one past its share).
    walltime : per job, SLURM's ``--time`` (``"02:00:00"``).  queue : partition
    (``-p``; None: the cluster's default).  account : ``-A`` (None: the user's
    default).  interface : network interface the workers reach this process on
    (``"ib0"``, ``"lo"`` on one machine; None: Dask's choice).  job_extra : more
    ``#SBATCH`` options (``["--qos=short"]``).  prologue : shell lines run before
    each worker starts (``["module load python/3.11", "source venv/bin/activate"]``).
    python : the workers' interpreter (default this one's).  local_directory :
    the workers' scratch folder (node-local disk).  notify : ``notify(line)`` for each job event (submitted,
    running, ended); None: logged (info).  Not part of what is asked of SLURM (not in :meth:`as_dict`).
    """

    jobs: int = 1
    cores: int = 1
    memory: str | None = None
    walltime: str = "01:00:00"
    queue: str | None = None
    account: str | None = None
    interface: str | None = None
    job_extra: tuple[str, ...] = ()
    prologue: tuple[str, ...] = ()
    python: str | None = None
    local_directory: str | None = None
    notify: Notify | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        from dask.utils import parse_bytes

        for name in ("jobs", "cores"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise BatchError(f"SLURM {name} must be a whole number of at least 1, got {getattr(self, name)!r}")
        if self.memory is not None:
            try:
                parse_bytes(str(self.memory))
            except ValueError:
                raise BatchError(f"SLURM memory must be like '4GB', got {self.memory!r}") from None
        if not _WALLTIME.match(str(self.walltime)):
            raise BatchError(f"SLURM walltime must be like '02:00:00' or '1-12:00:00', got {self.walltime!r}")
        for name in ("job_extra", "prologue"):
            value = getattr(self, name)
            object.__setattr__(self, name, (value,) if isinstance(value, str) else tuple(str(v) for v in value))

    @classmethod
    def from_profile(cls, path: str | os.PathLike, **overrides) -> "SlurmOptions":
        """The options of a TOML profile's ``[slurm]`` table, with ``overrides`` (not None) on top."""
        path = Path(path)
        try:
            document = tomllib.loads(path.read_text())
        except OSError as exc:
            raise BatchError(f"cannot read the SLURM profile {path}: {exc.strerror or exc}") from None
        except tomllib.TOMLDecodeError as exc:
            raise BatchError(f"{path}: not TOML: {exc}") from None
        table = document.get("slurm")
        if not isinstance(table, dict):
            raise BatchError(f"{path}: no [slurm] table (see the README's Corpus section)")
        known = {f.name for f in fields(cls)} - {"notify"}
        unknown = sorted(set(table) - known)
        if unknown:
            raise BatchError(f"{path}: unknown key(s) {', '.join(unknown)} in [slurm]; known: {', '.join(sorted(known))}")
        try:
            return replace(cls(**table), **{k: v for k, v in overrides.items() if v is not None})
        except BatchError as exc:
            raise BatchError(f"{path}: {exc}") from None

    def as_dict(self) -> dict:
        out = asdict(self)
        out.pop("notify")
        return out


@contextmanager
def slurm_cluster(options: SlurmOptions, log_directory: Path) -> Iterator[JobWatch]:
    """Submit ``options.jobs`` SLURM jobs of Dask workers; yield the :class:`JobWatch` (its ``client``); cancel
    the jobs on leaving.  A job SLURM refuses (partition, account, walltime over the limit) is a BatchError."""
    if slurm_version() is None:
        raise BatchError("--slurm needs SLURM's commands (sbatch, squeue) on this machine: run the batch on a "
                         "submit host of the cluster")
    log_directory.mkdir(parents=True, exist_ok=True)
    with _quiet_dask():
        yield from _cluster(options, log_directory, options.notify)


@contextmanager
def _quiet_dask() -> Iterator[None]:
    """Dask's scheduler, here in this process, logs every worker and key at INFO: warnings only while it
    runs (the batch says what matters: the jobs' starts and ends, the recordings lost)."""
    import distributed  # noqa: F401 - first: importing it sets its loggers' levels from its config

    with library_quieted("distributed", filters={"distributed.scheduler": _said_by_the_batch}):
        yield


def _said_by_the_batch(record: logging.LogRecord) -> bool:
    """False for the scheduler's error on a task whose worker died: the batch reports that recording as lost."""
    return "workers died while trying to run it" not in record.getMessage()


def _cluster(options: SlurmOptions, log_directory: Path, notify: Notify | None) -> Iterator[JobWatch]:
    import dask
    from dask_jobqueue import SLURMCluster
    from distributed import Client

    # One recording at a time per worker (none queued on a worker whose job may end), and a recording whose
    # worker dies is lost at once rather than tried on the next worker: both read when the scheduler starts.
    with dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):
        cluster = SLURMCluster(
            cores=options.cores, processes=options.cores, memory=options.memory or f"{2 * options.cores}GB",
            walltime=options.walltime, job_name=JOB_NAME, log_directory=os.fspath(log_directory),
            scheduler_options={"allowed_failures": 0, "dashboard": False},
            **{k: v for k, v in {"queue": options.queue, "account": options.account,
                                 "interface": options.interface, "python": options.python,
                                 "local_directory": options.local_directory}.items() if v is not None},
            job_extra_directives=list(options.job_extra), job_script_prologue=list(options.prologue))
    try:
        _check_submission(cluster.job_script())
        client = Client(cluster)
        try:
            cluster.scale(jobs=options.jobs)
            watch = JobWatch(cluster, client, log_directory, notify)
            _submitted(cluster, options.jobs, watch.notify)
            yield watch
            watch.release()
        finally:
            client.close()
    finally:
        _close(cluster)


def _submitted(cluster, jobs: int, notify: Notify, wait: float = 60.0) -> None:
    """Wait until ``sbatch`` took the jobs asked for.  dask-jobqueue submits in the background and only logs a
    refusal (a limit on jobs per user ...): none taken is a BatchError here, rather than a batch waiting for
    workers that never come; some taken, a line says so and the batch runs on those."""
    deadline = time.monotonic() + wait
    while True:
        taken = [job.job_id for job in list(cluster.workers.values()) if getattr(job, "job_id", None)]
        if len(taken) >= jobs or time.monotonic() > deadline:
            break
        time.sleep(0.1)
    if not taken:
        raise BatchError(f"SLURM took none of the {jobs} job(s) in {wait:.0f} s (sbatch's error is above)")
    if len(taken) < jobs:
        notify(f"SLURM took {len(taken)} of the {jobs} jobs (sbatch's error is above): running on those")


def _close(cluster) -> None:
    """Cancel the jobs (dask-jobqueue's close; ``scancel`` ourselves when it fails on a job never submitted)."""
    ids = [job.job_id for job in list(cluster.workers.values()) if getattr(job, "job_id", None)]
    try:
        cluster.close(timeout=30)
    except Exception as exc:  # noqa: BLE001 - closing must not hide the batch's own outcome
        logger.info("closing the SLURM cluster: %s: %s", type(exc).__name__, exc)
        if ids:
            subprocess.run(["scancel", *ids], capture_output=True, timeout=60)


def _check_submission(script: str) -> None:
    """``sbatch --test-only`` on the workers' job script: what SLURM would refuse, as one clear error now
    (dask-jobqueue submits in the background and only logs a refusal)."""
    with tempfile.NamedTemporaryFile("w", suffix=".sh", prefix="tonguevis-slurm-", delete=False) as fh:
        fh.write(script)
    try:
        run = subprocess.run(["sbatch", "--test-only", fh.name], capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        raise BatchError("sbatch --test-only did not answer in 60 s: is slurmctld running?") from None
    finally:
        os.unlink(fh.name)
    if run.returncode != 0:
        why = "; ".join(line.removeprefix("sbatch: error: ") for line in run.stderr.splitlines() if line.strip())
        raise BatchError(f"SLURM refuses the workers' job: {why or 'sbatch --test-only failed'}")
