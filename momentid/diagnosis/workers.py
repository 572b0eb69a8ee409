"""Independent re-simulations of a diagnosis on the machine's cores.

Trying the candidates of a step (stage 6's shortlist, a compound step's newcomers) means a few
independent jobs of seconds each, most of it MuJoCo replays with a Python force callback, one core
each; so do the per-run modal fits of recordings without added mass (:mod:`~momentid.diagnosis.real`).  :func:`run_forked` runs them on :data:`WORKERS` forked processes: the job and its inputs are
inherited by the fork, not pickled, and the re-simulations a worker memoised come back to the
parent's :class:`~momentid.diagnosis.refit.Refitter`, so nothing is computed twice.  Results are the
same as one after the other (each job is deterministic and single-threaded).
"""

from __future__ import annotations

from typing import Callable, Sequence

from threadpoolctl import threadpool_limits

from momentid.core.processes import forked_pool

__all__ = ["WORKERS", "run_forked"]

#: Worker processes: the 2 cores a lab laptop has.
WORKERS = 2

#: (job, tasks, refitter) of the running :func:`run_forked`, set before the pool forks.
_JOB: tuple | None = None


def _call(i: int):
    job, tasks, refitter = _JOB
    known = refitter.memo_keys() if refitter is not None else set()
    with threadpool_limits(limits=1, user_api="blas"):   # small dense products: threads only add waiting
        out = job(tasks[i])
    return out, refitter.new_memos(known) if refitter is not None else {}


def run_forked(job: Callable, tasks: Sequence, refitter=None) -> list:
    """``[job(task) for task in tasks]``, on :data:`WORKERS` forked processes when there are several.

    Parameters
    ----------
    job : callable
        One task -> a picklable result; may use ``refitter`` (its memos are handed back).
    tasks : sequence
        The jobs' inputs (not pickled: the workers inherit them).
    refitter : Refitter, optional
        The diagnosis's refitter, whose memos the workers extend (None: nothing to hand back).

    Returns
    -------
    list
        The results, in the order of ``tasks``.
    """
    if len(tasks) < 2:
        return [job(task) for task in tasks]
    global _JOB
    _JOB = (job, tasks, refitter)
    try:
        with forked_pool(min(WORKERS, len(tasks))) as pool:   # workers that die with the diagnosis
            results = list(pool.map(_call, range(len(tasks))))
    finally:
        _JOB = None
    for _, memos in results:
        if refitter is not None:
            refitter.absorb(memos)
    return [out for out, _ in results]
