"""A residual function evaluated at many points on the machine's cores.

The errors-in-variables fit (:mod:`momentid.estimation.eiv`) opens by scanning 41 scalings of its
start, each residual a few milliseconds of small dense algebra that holds the GIL.
:func:`point_map` evaluates the residual at a list of points on :data:`WORKERS` forked processes,
which inherit the function (only the points and the residuals are pickled).  In a worker process (a
diagnosis trial: the other worker keeps the other core busy) the points are evaluated one after the
other.  (The fit's Jacobians are exact and cost about one residual each:
:mod:`momentid.estimation.eiv_jacobian`.)
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator

import numpy as np
from threadpoolctl import threadpool_limits

from momentid.core.processes import borrow, forked_pool

__all__ = ["WORKERS", "point_map"]

#: Processes evaluating points: the 2 cores a lab laptop has.
WORKERS = 2

#: The function the running :func:`point_map` evaluates, set before its pool forks.
_FUN: Callable | None = None


def _evaluate(x: np.ndarray) -> np.ndarray:
    with threadpool_limits(limits=1, user_api="blas"):   # small dense products: threads only add waiting
        return _FUN(x)


@contextlib.contextmanager
def point_map(fun: Callable[[np.ndarray], np.ndarray], workers: int = WORKERS
              ) -> Iterator[Callable[[list], list]]:
    """A callable ``points -> [fun(x) for x in points]``, on ``workers`` forked processes.

    Parameters
    ----------
    fun : callable
        Deterministic and single-threaded: ``x`` (n,) -> residual (m,).  Inherited by the workers,
        not pickled; it must not change while the block runs.
    workers : int
        Processes.  Below 2 the points are evaluated here in turn; so they are until this process
        may start helpers (:func:`~momentid.core.processes.borrow`: the command may; a worker may
        once a core of its pool is idle, asked again at each call until it is).
    """
    if workers < 2 or _FUN is not None:
        yield lambda points: [fun(x) for x in points]
        return
    with contextlib.ExitStack() as stack:
        pool = None

        def evaluate(points: list) -> list:
            nonlocal pool
            if pool is None and len(points) > 1:
                pool = _started(stack, fun, workers)
            if pool is None:
                return [fun(x) for x in points]
            return list(pool.map(_evaluate, points, chunksize=max(1, math.ceil(len(points) / workers))))
        yield evaluate


def _started(stack: contextlib.ExitStack, fun: Callable, workers: int):
    """A pool of ``workers`` forked processes evaluating ``fun``, closed by ``stack`` (which then gives
    back the leave to start them), or None when this process may not start them now."""
    global _FUN
    release = borrow()
    if release is None:
        return None
    stack.callback(release)
    _FUN = fun
    stack.callback(_forget)
    return stack.enter_context(forked_pool(workers))


def _forget() -> None:
    global _FUN
    _FUN = None
