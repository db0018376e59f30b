"""The SLURM jobs of a batch as it runs: :class:`JobWatch` follows them (``squeue``) and their Dask workers.

It says when each job is submitted, waits, runs and ends; names the job a recording was lost
with; and tells the runner when every job has ended, so that the batch stops instead of waiting
for workers that will not come.  The batch polls it between results; ``squeue`` runs at most
every few seconds (a cluster's controller serves every user).
"""

from __future__ import annotations

import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from tonguevis._logging import logger

#: SLURM's job name for the batch's workers (what ``squeue`` shows).
JOB_NAME = "tonguevis-batch"
#: Job states after which no worker of the job runs ("ENDED": SLURM no longer knows the job).
ENDED = {"BOOT_FAIL", "CANCELLED", "COMPLETED", "DEADLINE", "FAILED", "NODE_FAIL", "OUT_OF_MEMORY", "PREEMPTED",
         "TIMEOUT", "ENDED"}
Notify = Callable[[str], None]


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

    def __init__(self, cluster, client, log_directory: Path, notify: Notify | None = None, every: float = 5.0):
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
        started = []
        for job in self.jobs.values():
            now = {name for name in workers if self.job_of(name) == job.id}
            if now - job.workers and job.state not in ENDED:
                started.append(job)
            job.workers |= now
        if started or force or time.monotonic() - self._last >= self.every:
            self._squeue()  # with a job's first worker: its node
        for job in started:  # SLURM's answer may lag its workers
            self._set(job, "RUNNING", job.node)
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
        if seen is None:  # SLURM did not answer: the states stay as they were (next time, maybe)
            return
        for job in live:
            state, node, reason = seen.get(job.id, ("ENDED", "", ""))
            if state == "PENDING" and job.state == "PENDING" and reason and reason != job.reason:
                job.reason = reason
                self.notify(f"SLURM job {job.id} pending ({reason})")
            self._set(job, state, node)


def squeue(ids: list[str]) -> dict[str, tuple[str, str, str]] | None:
    """{job id: (state, node, reason)} of ``ids`` as ``squeue`` says (ended jobs too, while SLURM remembers
    them; those it forgot are missing), or None when SLURM did not answer (nothing is known then)."""
    try:
        run = subprocess.run(["squeue", "--noheader", "--states=all", f"--jobs={','.join(ids)}",
                              "--format=%i|%T|%N|%r"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if run.returncode != 0:
        # one id SLURM forgot is an error; several forgotten are an empty answer
        return {} if "Invalid job id" in run.stderr else None
    seen = {}
    for line in run.stdout.splitlines():
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
