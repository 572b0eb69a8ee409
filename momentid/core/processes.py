"""Processes: workers that die with their parent, and the signals a command handles.

A forked worker blocked on its task queue outlives a parent killed by SIGTERM or SIGKILL: it is
re-parented to init and waits forever, holding its memory (120-170 MB for a diagnosis trial).
:func:`forked_pool` is the one way momentid starts worker processes (diagnosis trials, simulated
runs with callback physics, sweep cases): every worker asks the kernel to kill it when its parent
dies (:func:`die_with_parent`), and leaving the pool by an exception (Ctrl-C, or SIGTERM, which the
command line turns into Ctrl-C) kills the workers at once instead of waiting for their tasks.

Who may start workers: the command (:func:`may_fork`); a worker only while it holds a core of its
pool that has no task left (:func:`lending`, :func:`helpers_allowed`), so that the last, longest
task of a batch does not run on one core while the other waits.

Independent jobs of seconds each (a diagnosis's candidates, a compound step's newcomers, the per-run
modal fits, the twin's folds) run on :data:`WORKERS` forked processes through :func:`run_forked`: the
job and its inputs are inherited by the fork, not pickled, and each job returns everything the caller
needs from it as a value; nothing else comes back from a worker.  Results are the same as one after
the other (each job is deterministic and single-threaded).

A command (:func:`momentid.cli.main`) handles SIGTERM like Ctrl-C (:func:`sigterm_as_interrupt`:
outputs are closed as on an interrupt, and it exits 143), and a reader of its output that goes away
ends it quietly (:func:`quiet_broken_pipe`: exit 141, no text).
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import multiprocessing
import os
import signal
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor, as_completed
from collections.abc import Callable, Iterator, Sequence

from threadpoolctl import threadpool_limits

__all__ = ["borrow", "die_with_parent", "forked_pool", "helpers_allowed", "in_background", "lending", "may_fork",
           "NESTING", "PARENT_POLL_S", "Terminated", "sigterm_as_interrupt", "quiet_broken_pipe", "run_forked",
           "run_threaded", "WORKERS"]

#: Processes fork helpers of their own above this depth: the command (depth 0), not its workers (a
#: diagnosis trial's errors-in-variables fit parallelised inside a worker measured no faster: the
#: other worker keeps the cores busy).
NESTING = 1
#: This process's depth: 0 in the command, one more in each forked worker (set as it starts).
_DEPTH = 0

#: ``prctl`` option asking for a signal when the parent dies (linux/prctl.h).
PR_SET_PDEATHSIG = 1
#: Where ``prctl`` does not exist (not Linux): how often (s) a worker's watchdog thread checks that
#: its parent is alive.
PARENT_POLL_S = 0.5


def _watch(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def die_with_parent(parent: int) -> None:
    """In a worker forked by process ``parent``: die when the parent does.

    Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)``, so the kernel kills the worker the moment its
    parent ends, however it ends; a parent already gone before the request is caught by
    comparing ``os.getppid()``.  Elsewhere (no ``prctl``): a daemon thread polls ``os.getppid()``
    every :data:`PARENT_POLL_S` seconds and exits the worker once it has been re-parented.
    SIGTERM is restored to its default (the command line's handler, inherited by the fork, would
    turn it into a KeyboardInterrupt that the pool reports as the task's result).
    """
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0:
            if os.getppid() != parent:
                os._exit(1)
            return
    threading.Thread(target=_watch, args=(parent,), daemon=True, name="momentid-parent-watch").start()


def _deeper() -> None:
    global _DEPTH
    _DEPTH += 1


def may_fork() -> bool:
    """Whether this process may start helper processes: fork exists, it is not too deep
    (:data:`NESTING`), and it is not a daemonic process (a worker of the caller's own
    ``multiprocessing.Pool``, which may have no children: there the work runs in the process itself)."""
    return ("fork" in multiprocessing.get_all_start_methods() and _DEPTH < NESTING
            and not multiprocessing.current_process().daemon)


#: Cores of the running pool of :func:`lending` whose worker has no task left: a semaphore its
#: workers' tasks borrow from (:func:`helpers_allowed`); None outside such a pool.
_IDLE = None


@contextlib.contextmanager
def lending() -> Iterator[Callable[[int], None]]:
    """Around a pool of workers forked in the block: yields ``idle(n)``, which the command calls
    with how many of the pool's workers have no task left; each such core is lent, one at a time,
    to a task still running (:func:`helpers_allowed`), so that the last and longest task of a batch
    does not run on one core while the other waits.  (Forked helpers change no result: each job is
    deterministic and single-threaded.)"""
    global _IDLE
    if not may_fork():
        yield lambda n: None
        return
    _IDLE = multiprocessing.get_context("fork").Semaphore(0)
    lent = 0

    def idle(n: int) -> None:
        nonlocal lent
        while lent < n:
            _IDLE.release()
            lent += 1
    try:
        yield idle
    finally:
        _IDLE = None


def borrow() -> Callable[[], None] | None:
    """Leave to start helper processes now: a callable that gives it back, or None.  The command has
    it (:func:`may_fork`); a worker of a :func:`lending` pool has it while it holds one of the pool's
    idle cores (the helpers, deeper, start none of their own)."""
    if may_fork():
        return lambda: None
    idle = _IDLE
    if _DEPTH != NESTING or idle is None or not idle.acquire(block=False):
        return None
    return idle.release


@contextlib.contextmanager
def helpers_allowed() -> Iterator[bool]:
    """Whether this process may start helper processes for the block (:func:`borrow`, given back
    when the block ends)."""
    release = borrow()
    try:
        yield release is not None
    finally:
        if release is not None:
            release()


#: Seconds an interrupted pool's manager thread is given to end (it ends within milliseconds once its
#: workers are killed).
MANAGER_GRACE_S = 5.0


def _start(parent: int, initializer: Callable | None, initargs: tuple) -> None:
    _deeper()
    die_with_parent(parent)
    if initializer is not None:
        initializer(*initargs)


@contextlib.contextmanager
def forked_pool(workers: int, initializer: Callable | None = None, initargs: tuple = ()
                ) -> Iterator[ProcessPoolExecutor]:
    """A ``ProcessPoolExecutor`` of ``workers`` forked processes (spawned where fork does not exist)
    that die with this process, and are killed when the ``with`` block is left by an exception.

    Parameters
    ----------
    workers : int
        Worker processes.
    initializer, initargs
        As for ``ProcessPoolExecutor``: run in each worker after :func:`die_with_parent`.
    """
    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("fork" if "fork" in methods else None)
    before = {p.pid for p in multiprocessing.active_children()}
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_start,
                               initargs=(os.getpid(), initializer, initargs))
    try:
        yield pool
    except BaseException:
        # Interrupted: the tasks' results are not wanted; do not wait for them.  The pool's manager
        # thread, which sees the workers gone and ends, is given a few seconds to: one left running
        # races the interpreter's exit (CPython 3.11's exit hook writes to its wake-up pipe as the
        # thread closes it: "Exception ignored ... Bad file descriptor" after the command's last line).
        # Shutting down with wait=True instead can deadlock (its queue's feeder blocks on a pipe that
        # the killed workers no longer read).
        manager = getattr(pool, "_executor_manager_thread", None)
        pool.shutdown(wait=False, cancel_futures=True)
        for child in multiprocessing.active_children():
            if child.pid not in before:
                child.kill()
        if manager is not None:
            manager.join(timeout=MANAGER_GRACE_S)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _background_child(job: Callable, send, parent: int) -> None:
    global _DEPTH
    _DEPTH = NESTING   # a job on speculation keeps to one core: it starts no helpers of its own
    die_with_parent(parent)
    try:
        out = (True, job())
    except BaseException as exc:   # noqa: BLE001  (re-raised in the parent)
        out = (False, exc)
    try:
        send.send(out)
    except Exception as exc:       # noqa: BLE001  (an unpicklable result or error: say so)
        send.send((False, RuntimeError(f"background job's result could not be sent back: {exc}")))
    send.close()


@contextlib.contextmanager
def in_background(job: Callable[[], object]) -> Iterator[Callable[[], object]]:
    """Start ``job()`` in a forked process (which inherits it: nothing is pickled but its result);
    yields a callable returning the result (re-raising the job's exception).  A job whose result is
    not asked for is killed when the block is left (work started on speculation, not needed).

    In a process too deep to fork (:func:`may_fork`), or where fork does not exist, the job runs
    here, when its result is first asked for.
    """
    if not may_fork():
        done: list = []

        def here():
            if not done:
                done.append(job())
            return done[0]
        yield here
        return
    context = multiprocessing.get_context("fork")
    receive, send = context.Pipe(duplex=False)
    process = context.Process(target=_background_child, args=(job, send, os.getpid()), daemon=True)
    process.start()
    send.close()
    got: list = []

    def result():
        if not got:
            try:
                got.append(receive.recv())
            except EOFError:
                got.append((False, RuntimeError(f"background job died (exit code {process.exitcode})")))
            process.join()
        ok, value = got[0]
        if not ok:
            raise value
        return value
    try:
        yield result
    finally:
        if process.is_alive():
            process.kill()
        process.join()
        receive.close()


class Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C: outputs are closed as on an interrupt (a recording keeps its
    completed runs and notes the signal), worker processes are stopped, and the command exits 143
    (128 + SIGTERM)."""

    def __str__(self) -> str:
        return "SIGTERM"


def _raise_terminated(signum, frame) -> None:
    raise Terminated


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """While the block runs, SIGTERM raises :class:`Terminated` (main thread only: elsewhere Python
    cannot install handlers, and the default, dying at once, stays)."""
    try:
        old = signal.signal(signal.SIGTERM, _raise_terminated)
    except ValueError:   # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def quiet_broken_pipe() -> int:
    """The reader of stdout went away (``momentid identify --json | head -c 10``): nothing more is
    written there (stdout now points at /dev/null, so the interpreter's last flush cannot complain
    either); returns 141 (128 + SIGPIPE, what a shell shows for a pipeline's writer)."""
    with contextlib.suppress(OSError, ValueError, AttributeError, io.UnsupportedOperation):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    return 128 + signal.SIGPIPE


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
    and this process may start them (:func:`helpers_allowed`: the command,
    or a worker's task while a core of its pool is idle).  The cores of workers with no task left
    are lent to the tasks still running (:func:`lending`).

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


def run_threaded(job: Callable, tasks: Sequence) -> list:
    """``[job(task) for task in tasks]``, on :data:`WORKERS` threads when there are several and this
    process may use more cores (:func:`helpers_allowed`, as :func:`run_forked`): for jobs that spend
    their time where the GIL is released (a MuJoCo rollout with no Python callback), threads start no
    process and copy nothing.  Results in the order of ``tasks``, the same as one after the other
    (each job deterministic, single-threaded, and touching nothing another one uses).
    """
    if len(tasks) < 2:
        return [job(task) for task in tasks]
    with helpers_allowed() as allowed:
        if not allowed:
            return [job(task) for task in tasks]
        pool = ThreadPoolExecutor(min(WORKERS, len(tasks)))
        try:
            with threadpool_limits(limits=1, user_api="blas"):
                return list(pool.map(job, tasks))
        except BaseException:
            # Interrupted (Ctrl-C, SIGTERM): the tasks not started are dropped; those running end with
            # their replay
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        finally:
            pool.shutdown(wait=True)
