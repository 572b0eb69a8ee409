"""Independent re-simulations of a diagnosis on the machine's cores.

Trying the candidates of a step (stage 6's shortlist, a compound step's newcomers) means a few
independent jobs of seconds each, most of it MuJoCo replays with a Python force callback, one core
each; so do the per-run modal fits of recordings without added mass (:mod:`~momentid.diagnosis.real`).
:func:`run_forked` runs them on :data:`WORKERS` forked processes: the job and its inputs are
inherited by the fork, not pickled, and each job returns everything the caller needs from it as a
value (a :class:`~momentid.diagnosis.selection.Tried`, a compound trial), which the caller records
where it reuses it; nothing else comes back from a worker.  Results are the same as one after the
other (each job is deterministic and single-threaded).
"""

from __future__ import annotations

from concurrent.futures import as_completed
from typing import Callable, Sequence

from threadpoolctl import threadpool_limits

from momentid.core.processes import forked_pool, helpers_allowed, lending

__all__ = ["WORKERS", "run_forked"]

#: Worker processes: the 2 cores a lab laptop has.
WORKERS = 2

#: (job, tasks) of the running :func:`run_forked`, set before the pool forks (read by the workers).
_JOB: tuple | None = None


def _call(i: int):
    job, tasks = _JOB
    with threadpool_limits(limits=1, user_api="blas"):   # small dense products: threads only add waiting
        return job(tasks[i])


def run_forked(job: Callable, tasks: Sequence) -> list:
    """``[job(task) for task in tasks]``, on :data:`WORKERS` forked processes when there are several
    and this process may start them (:func:`~momentid.core.processes.helpers_allowed`: the command,
    or a worker's task while a core of its pool is idle).  The cores of workers with no task left
    are lent to the tasks still running (:func:`~momentid.core.processes.lending`).

    Parameters
    ----------
    job : callable
        One task -> a picklable result: everything the caller needs from the job.
    tasks : sequence
        The jobs' inputs (not pickled: the workers inherit them).

    Returns
    -------
    list
        The results, in the order of ``tasks``.
    """
    if len(tasks) < 2:
        return [job(task) for task in tasks]
    with helpers_allowed() as allowed:
        if not allowed:
            return [job(task) for task in tasks]
        return _forked(job, tasks)


def _forked(job: Callable, tasks: Sequence) -> list:
    global _JOB
    outer, _JOB = _JOB, (job, tasks)   # (a worker's own task is the outer job: restored after)
    n = min(WORKERS, len(tasks))
    try:
        with lending() as idle, forked_pool(n) as pool:   # workers that die with the diagnosis
            futures = [pool.submit(_call, i) for i in range(len(tasks))]
            for done, _ in enumerate(as_completed(futures), start=1):
                idle(n - min(n, len(tasks) - done))   # workers with no task left lend their cores
            return [f.result() for f in futures]
    finally:
        _JOB = outer
