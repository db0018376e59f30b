"""The batch on a SLURM cluster: dask-jobqueue submits one-thread Dask workers as SLURM jobs.

:class:`SlurmOptions` says what to ask SLURM for (``--slurm-jobs``, ``--slurm-cores`` ...,
or a lab's TOML profile); :func:`slurm_cluster` submits the jobs and yields a Dask client
and a :class:`JobWatch`, which :func:`tonguevis.batch.runners.run_dask` polls.  The
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
from typing import Callable, Iterator

from tonguevis.batch.settings import BatchError

from tonguevis._logging import logger

#: SLURM's job name for the batch's workers (what ``squeue`` shows).
JOB_NAME = "tonguevis-batch"
#: Job states after which no worker of the job runs.
ENDED = {"BOOT_FAIL", "CANCELLED", "COMPLETED", "DEADLINE", "FAILED", "NODE_FAIL", "OUT_OF_MEMORY", "PREEMPTED",
         "TIMEOUT", "ENDED"}
_WALLTIME = re.compile(r"^(\d+-)?\d+(:\d{1,2}){0,2}$")  # SLURM's forms: M, M:S, H:M:S, D-H, D-H:M, D-H:M:S
Notify = Callable[[str], None]


@dataclass(frozen=True)
class SlurmOptions:
    """What each SLURM job asks for, and how many.

    jobs : SLURM jobs submitted.  cores : CPU cores per job, each running one
    one-thread worker process.  memory : per job (``"8GB"``; default 2 GB per
    core: a worker takes 0.4-0.6 GB, Dask restarts one past its share).
    walltime : per job, SLURM's ``--time`` (``"02:00:00"``).  queue : partition
    (``-p``; None: the cluster's default).  account : ``-A`` (None: the user's
    default).  interface : network interface the workers reach this process on
    (``"ib0"``, ``"lo"`` on one machine; None: Dask's choice).  job_extra : more
    ``#SBATCH`` options (``["--qos=short"]``).  prologue : shell lines run before
    each worker starts (``["module load python/3.11", "source venv/bin/activate"]``).
    python : the workers' interpreter (default this one's).  local_directory :
    the workers' scratch folder (node-local disk).
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
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(table) - known)
        if unknown:
            raise BatchError(f"{path}: unknown key(s) {', '.join(unknown)} in [slurm]; known: {', '.join(sorted(known))}")
        try:
            return replace(cls(**table), **{k: v for k, v in overrides.items() if v is not None})
        except BatchError as exc:
            raise BatchError(f"{path}: {exc}") from None

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class Job:
    """One SLURM job of the batch, as last seen: state, node, its workers' names, the recordings done and lost."""

    id: str
    state: str = "PENDING"
    node: str = ""
    reason: str = ""
    workers: set[str] = field(default_factory=set)
    done: list[str] = field(default_factory=list)
    lost: list[str] = field(default_factory=list)

    def as_dict(self) -> dict:
        return {"state": self.state, "node": self.node, "recordings": self.done, "lost": self.lost}


class JobWatch:
    """Follows the batch's SLURM jobs (``squeue``) and their Dask workers; says when they start and end.

    :meth:`poll` is called by the runner between results; it calls ``notify`` with one line per
    event and returns why no recording can run any more (every job ended), else None.
    """

    def __init__(self, cluster, client, log_directory: Path, notify: Notify | None = None, every: float = 2.0):
        self.cluster, self.client, self.log_directory = cluster, client, log_directory
        self.notify = notify or (lambda message: logger.info("%s", message))
        self.every = every
        self.jobs: dict[str, Job] = {}
        self._names: dict[str, str] = {}  # dask-jobqueue's job name -> SLURM job id (kept after the job is gone)
        self._last = 0.0
        self.version = slurm_version()

    # ---------------------------------------------------------------- what the runner asks
    def poll(self, force: bool = False) -> str | None:
        """Update the jobs and workers (``squeue`` at most every ``every`` s unless ``force``); the reason no
        recording can run any more, or None."""
        for name, job in list(self.cluster.workers.items()):
            if getattr(job, "job_id", None) and name not in self._names:
                self._names[name] = job.job_id
                self.jobs[job.job_id] = Job(job.job_id)
                self.notify(f"SLURM job {job.job_id} submitted ({JOB_NAME})")
        workers = self._workers()
        for job in self.jobs.values():
            now = {name for name in workers if self.job_of(name) == job.id}
            if now - job.workers and job.state not in ENDED:
                self._set(job, "RUNNING", job.node)
            job.workers |= now
        if force or time.monotonic() - self._last >= self.every or (self.jobs and not workers):
            self._squeue()
        if self.jobs and not workers and all(j.state in ENDED for j in self.jobs.values()):
            return "every SLURM job of the batch has ended (" + ", ".join(
                f"{j.id}: {j.state}" for j in self.jobs.values()) + ")"
        return None

    def job_of(self, worker_name: str | None) -> str | None:
        """The SLURM job id of a worker (dask-jobqueue names a job's workers after the job: NAME or NAME-k)."""
        if worker_name is None:
            return None
        return self._names.get(worker_name) or self._names.get(str(worker_name).rsplit("-", 1)[0])

    def done(self, file: str, job_id: str | None) -> None:
        if job_id in self.jobs:
            self.jobs[job_id].done.append(file)

    def lost(self, file: str, exc: BaseException) -> str:
        """Why ``file``'s task failed with its worker (``KilledWorker`` and the like): the message of a lost recording."""
        worker = getattr(exc, "last_worker", None)
        job_id = self.job_of(getattr(worker, "name", None))
        if job_id is None:
            return f"its Dask worker died ({type(exc).__name__}); run the same command again to resume"
        job = self.jobs[job_id]
        job.lost.append(file)
        deadline = time.monotonic() + 15.0
        self._squeue()
        while job.state == "COMPLETING" and time.monotonic() < deadline:  # its final state is moments away
            time.sleep(0.2)
            self._squeue()
        if job.state in ENDED:
            return f"lost with SLURM job {job_id} ({job.state}); run the same command again to resume"
        return (f"its worker in SLURM job {job_id} died while the job runs (over its memory? see the job's log "
                f"in {self.log_directory}); run the same command again to resume")

    def release(self) -> None:
        """Say that the jobs still there are let go (cancelled by the batch, its work done)."""
        for job in self.jobs.values():
            if job.state not in ENDED:
                self.notify(f"SLURM job {job.id} released after {len(job.done)} recording(s)")

    def record(self) -> dict:
        """What batch.json keeps of the jobs: SLURM's version and, per job id, its state, node, recordings."""
        return {"version": self.version, "jobs": {job_id: job.as_dict() for job_id, job in self.jobs.items()}}

    # ---------------------------------------------------------------- SLURM and Dask
    def _workers(self) -> set[str]:
        info = self.client.scheduler_info()["workers"]  # every worker (n_workers=-1)
        return {w.get("name") for w in info.values()}

    def _set(self, job: Job, state: str, node: str) -> None:
        if state == job.state:
            return
        job.state, job.node = state, node or job.node
        where = f" on {job.node}" if job.node else ""
        if state in ENDED:
            lost = f"; lost: {', '.join(job.lost)}" if job.lost else ""
            self.notify(f"SLURM job {job.id} ended: {state}{where} after {len(job.done)} recording(s){lost}")
        elif state == "RUNNING":
            self.notify(f"SLURM job {job.id} running{where}")
        elif state not in ("PENDING", "CONFIGURING", "COMPLETING"):  # passing states say nothing new
            self.notify(f"SLURM job {job.id} {state.lower()}")

    def _squeue(self) -> None:
        self._last = time.monotonic()
        live = [j for j in self.jobs.values() if j.state not in ENDED]
        if not live:
            return
        seen = squeue([j.id for j in live])
        for job in live:
            state, node, reason = seen.get(job.id, ("ENDED", "", ""))
            if state == "PENDING" and job.state == "PENDING" and reason and reason != job.reason:
                job.reason = reason
                self.notify(f"SLURM job {job.id} pending ({reason})")
            self._set(job, state, node)


def squeue(ids: list[str]) -> dict[str, tuple[str, str, str]]:
    """{job id: (state, node, reason)} of ``ids`` as ``squeue`` says (ended jobs too, while SLURM remembers them)."""
    try:
        out = subprocess.run(["squeue", "--noheader", "--states=all", f"--jobs={','.join(ids)}",
                              "--format=%i|%T|%N|%r"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.TimeoutExpired):
        return {}
    seen = {}
    for line in out.splitlines():
        parts = line.strip().split("|")
        if len(parts) == 4:
            seen[parts[0]] = (parts[1], parts[2], parts[3] if parts[3] not in ("None", "(null)") else "")
    return seen


def slurm_version() -> str | None:
    """``sbatch --version`` (e.g. "slurm-wlm 22.05.8"), or None without SLURM."""
    try:
        return subprocess.run(["sbatch", "--version"], capture_output=True, text=True, timeout=30).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        return None


@contextmanager
def slurm_cluster(options: SlurmOptions, log_directory: Path, notify: Notify | None = None) -> Iterator[JobWatch]:
    """Submit ``options.jobs`` SLURM jobs of Dask workers; yield the :class:`JobWatch` (its ``client``); cancel
    the jobs on leaving.  A job SLURM refuses (partition, account, walltime over the limit) is a BatchError."""
    if slurm_version() is None:
        raise BatchError("--slurm needs SLURM's commands (sbatch, squeue) on this machine: run the batch on a "
                         "submit host of the cluster")
    log_directory.mkdir(parents=True, exist_ok=True)
    with _quiet_dask():
        yield from _cluster(options, log_directory, notify)


@contextmanager
def _quiet_dask() -> Iterator[None]:
    """Dask's scheduler, here in this process, logs every worker and key at INFO: warnings only while it
    runs (the batch says what matters: the jobs' starts and ends, the recordings lost)."""
    import distributed  # noqa: F401 - first: importing it sets its loggers' levels from its config

    dask_logger = logging.getLogger("distributed")
    level = dask_logger.level
    dask_logger.setLevel(max(level, logging.WARNING))
    scheduler = logging.getLogger("distributed.scheduler")
    scheduler.addFilter(_said_by_the_batch)
    try:
        yield
    finally:
        scheduler.removeFilter(_said_by_the_batch)
        dask_logger.setLevel(level)


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
            yield watch
            watch.release()
        finally:
            client.close()
    finally:
        try:
            cluster.close(timeout=30)  # scancel of the jobs still there
        except Exception as exc:  # noqa: BLE001 - closing must not hide the batch's own outcome
            logger.warning("closing the SLURM cluster: %s: %s", type(exc).__name__, exc)


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
