"""Where the tasks run: in this process, in joblib's loky worker processes, or on a Dask cluster (SLURM's too).

Each runner calls ``on_done(outcome)`` in the parent as every recording
finishes, in completion order.  The parent has already built the model's
modal basis (disk cache) and compiled the warp kernels (kernel cache), so
workers load both instead of computing them at once.
"""

from __future__ import annotations

import time
import uuid
from typing import Callable

from tonguevis.batch.settings import BatchError, ModelSpec
from tonguevis.batch.tasks import Outcome, Task, process

OnDone = Callable[[Outcome], None]
#: Seconds between looks at the SLURM jobs while no result comes.
POLL_SECONDS = 0.25


def run_here(tasks: list[Task], spec: ModelSpec, on_done: OnDone) -> None:
    """One after the other in this process (``jobs=1``)."""
    for task in tasks:
        on_done(process(task, spec))


def run_loky(tasks: list[Task], spec: ModelSpec, jobs: int, on_done: OnDone) -> None:
    """``jobs`` loky worker processes with one BLAS/OpenMP thread each; results as they finish."""
    from joblib import Parallel, delayed
    from joblib.externals.loky.process_executor import TerminatedWorkerError

    parallel = Parallel(n_jobs=jobs, backend="loky", inner_max_num_threads=1, return_as="generator_unordered",
                        pre_dispatch="2*n_jobs", batch_size=1)
    try:
        for outcome in parallel(delayed(process)(task, spec) for task in tasks):
            on_done(outcome)
    except TerminatedWorkerError as exc:
        raise BatchError("a worker process died (out of memory?); the recordings finished so far are kept: "
                         f"rerun to resume ({exc})") from exc


def run_dask(tasks: list[Task], spec: ModelSpec, client, on_done: OnDone, watch=None) -> None:
    """On a Dask distributed cluster through ``client``; a task lost with its worker is recorded as a failure.

    watch : a :class:`tonguevis.batch.slurm.JobWatch` when the workers are SLURM jobs: polled between
        results (the jobs' starts and ends), it names the job a recording was lost with, and says when
        every job has ended: the recordings not started are then reported lost too and the run returns.
    """
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    if not tasks:
        return
    run = uuid.uuid4().hex[:8]
    # Scattered data lives on the workers it was sent to; SLURM jobs end (scancel, walltime) and take theirs
    # with them, so there the (small) spec goes with each task instead.
    shared = spec if watch is not None else client.scatter(spec, broadcast=True)
    # Each future is let go once its outcome is here: a result kept on a worker whose job then ends would be
    # computed again elsewhere (Dask recomputes what its client still holds), and counted twice.
    pending = {client.submit(process, task, shared, key=f"tonguevis-{run}-{k}-{task.file}"): task
               for k, task in enumerate(tasks)}
    try:
        completed = as_completed(pending)
        while pending:
            finished = completed.next_batch(block=watch is None)
            if watch is not None:
                ended = watch.poll()
                if not finished and ended:
                    for task in pending.values():
                        on_done(Outcome(task.file, failure=("lost", f"not started: {ended}; run the same "
                                                                    "command again to resume")))
                    return
                if not finished:
                    time.sleep(POLL_SECONDS)
            for future in finished:
                task = pending.pop(future)
                try:
                    outcome = future.result()
                except Exception as exc:  # noqa: BLE001 - the worker died or the task could not run there
                    if watch is not None and isinstance(exc, KilledWorker):
                        outcome = Outcome(task.file, failure=("lost", watch.lost(task.file, exc)))
                    else:
                        outcome = Outcome(task.file, failure=("worker", f"{type(exc).__name__}: {exc}"))
                else:
                    if watch is not None:
                        watch.done(outcome.file, outcome.slurm_job)
                finally:
                    future.release()
                on_done(outcome)
    finally:
        client.cancel(list(pending))
