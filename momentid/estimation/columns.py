"""A residual function evaluated at many points on the machine's cores: finite-difference Jacobians.

The errors-in-variables fit (:mod:`momentid.estimation.eiv`) spends most of its time on
forward-difference Jacobians: one residual evaluation per parameter (36 for a 5-storey rig), each a
few milliseconds of small dense algebra that holds the GIL.  :func:`point_map` evaluates the
residual at a list of points on :data:`WORKERS` forked processes, which inherit the function (only
the points and the residuals are pickled); :func:`forward_jacobian` is scipy's ``'2-point'``
Jacobian (the same steps and the same arithmetic, so the same numbers, bit for bit) with its columns
evaluated that way.  In a worker process (a diagnosis trial: the other worker keeps the other core
busy) the points are evaluated one after the other.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator

import numpy as np
from threadpoolctl import threadpool_limits

from momentid.core.processes import borrow, forked_pool

__all__ = ["WORKERS", "point_map", "forward_jacobian", "Cached"]

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


class Cached:
    """``fun`` remembering its last point and value (a Jacobian at the point scipy just evaluated)."""

    def __init__(self, fun: Callable[[np.ndarray], np.ndarray]):
        self.fun, self.x, self.f = fun, None, None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        f = self.fun(x)
        self.x, self.f = np.array(x, copy=True), f
        return f

    def at(self, x: np.ndarray) -> np.ndarray:
        """``fun(x)``, from memory when ``x`` was the last point."""
        if self.x is not None and self.x.shape == x.shape and np.array_equal(self.x, x):
            return self.f
        return self(x)


def forward_jacobian(fun: Cached, x: np.ndarray, evaluate: Callable[[list], list]) -> np.ndarray:
    """scipy's ``'2-point'`` Jacobian of ``fun`` at ``x`` (``approx_derivative`` without bounds:
    relative step ``sqrt(eps)``, at least ``sqrt(eps)`` absolute), its columns by ``evaluate``.

    Parameters
    ----------
    fun : Cached
        The residual; its value at ``x`` is reused when it was the last point evaluated.
    x : ndarray, shape (n,)
    evaluate : callable
        ``points -> values`` (:func:`point_map`).

    Returns
    -------
    ndarray, shape (m, n)
    """
    x = np.asarray(x, float)
    f0 = fun.at(x)
    sign = (x >= 0).astype(float) * 2 - 1
    h = np.finfo(np.float64).eps ** 0.5 * sign * np.maximum(1.0, np.abs(x))
    points = []
    for i in range(x.size):
        x1 = np.copy(x)
        x1[i] = x[i] + h[i]
        points.append(x1)
    J = np.empty((x.size, f0.size))
    for i, f in enumerate(evaluate(points)):
        J[i] = (f - f0) / ((x[i] + h[i]) - x[i])
    return J.T
