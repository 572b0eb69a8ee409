"""Counters of work done, shared with the threads and forked workers that do it: how many replays a
diagnosis makes (``benchmarks/``), whichever process or thread made them.

:func:`counting` starts a counter in shared memory, inherited by every worker forked while it runs;
:func:`add` (called by the code that does the work: :func:`momentid.lab.simulation.replay`,
:func:`momentid.lab.resim.simulate`) adds to it when one runs, and costs nothing otherwise.
"""

from __future__ import annotations

import contextlib
import multiprocessing
from collections.abc import Callable, Iterator

__all__ = ["REPLAYS", "add", "counting"]

#: Runs of a model through a recorded table motion (one model, one run: one replay).
REPLAYS = "replays"

_RUNNING: dict = {}   # name -> shared multiprocessing.Value, while counting


def add(name: str, n: int = 1) -> None:
    """Add ``n`` to the counter ``name`` when it is being counted (:func:`counting`)."""
    value = _RUNNING.get(name)
    if value is not None:
        with value.get_lock():
            value.value += n


@contextlib.contextmanager
def counting(name: str = REPLAYS) -> Iterator[Callable[[], int]]:
    """Count ``name`` in the block (in this process, its threads and the workers it forks meanwhile):
    yields a callable returning the count so far."""
    outer = _RUNNING.get(name)
    value = _RUNNING[name] = multiprocessing.get_context("fork" if "fork" in multiprocessing.get_all_start_methods()
                                                         else None).Value("q", 0)
    try:
        yield lambda: int(value.value)
    finally:
        if outer is None:
            del _RUNNING[name]
        else:
            _RUNNING[name] = outer
            add(name, int(value.value))   # an outer count includes the inner one's
