"""Workers die with their parent (issue 22 point 5): killing a command during its forked work
(SIGTERM or SIGKILL) leaves no worker process behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import momentid as mi
from momentid.core.processes import forked_pool

from conftest import SCENARIOS

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
#: The issue's bound: no process left this long after the kill.
GONE_WITHIN_S = 5.0


def _children(pid: int) -> list[int]:
    """Live (not zombie) processes whose parent is ``pid`` (Linux /proc)."""
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        state, ppid = stat[stat.rindex(")") + 2:].split()[:2]
        if int(ppid) == pid and state != "Z":
            out.append(int(entry))
    return out


def _alive(pids) -> list[int]:
    alive = []
    for pid in pids:
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            continue
        if stat[stat.rindex(")") + 2] != "Z":
            alive.append(pid)
    return alive


def _workers_of(proc: subprocess.Popen, count: int, timeout: float = 300) -> list[int]:
    """Wait until ``proc`` has ``count`` forked workers (children running its own command line)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read()
        cmdline = Path(f"/proc/{proc.pid}/cmdline").read_bytes()   # read again: it changes at exec
        kids = []
        for k in _children(proc.pid):
            try:
                if Path(f"/proc/{k}/cmdline").read_bytes() == cmdline:
                    kids.append(k)
            except OSError:
                pass
        if len(kids) >= count:
            return kids
        time.sleep(0.05)
    raise AssertionError(f"no {count} workers within {timeout} s")


def _kill_and_check(proc: subprocess.Popen, workers: list[int], sig: int) -> None:
    proc.send_signal(sig)
    proc.wait(timeout=60)
    deadline = time.monotonic() + GONE_WITHIN_S
    while _alive(workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = _alive(workers)
    for pid in left:   # do not leave them to the next test
        os.kill(pid, signal.SIGKILL)
    assert not left, f"workers {left} outlived their parent by {GONE_WITHIN_S} s ({signal.Signals(sig).name})"


_POOL = """
import time
from momentid.core.processes import forked_pool
with forked_pool(2) as pool:
    list(pool.map(time.sleep, [3600, 3600]))
"""


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_pool_workers_die_with_their_parent(sig):
    """A pool whose workers block for an hour: killing the parent ends them within seconds."""
    proc = subprocess.Popen([sys.executable, "-c", _POOL], env=ENV, stderr=subprocess.PIPE, text=True)
    _kill_and_check(proc, _workers_of(proc, 2), sig)


def test_interrupted_pool_leaves_no_thread_running():
    """Leaving the pool by an interrupt ends its manager thread before the exception goes on: one
    left running races the interpreter's exit, whose hook then writes to a pipe the thread closes
    ("Exception ignored ... Bad file descriptor" after "error: terminated (SIGTERM)", seen in CI)."""
    before = set(threading.enumerate())
    with pytest.raises(KeyboardInterrupt), forked_pool(2) as pool:
        for i in range(40):
            pool.submit(time.sleep, 0.01 * i)
        time.sleep(0.05)
        raise KeyboardInterrupt
    assert [t.name for t in set(threading.enumerate()) - before if t.is_alive()] == []


@pytest.fixture(scope="module")
def friction_recording(tmp_path_factory):
    """A hidden rig whose diagnosis tries its shortlist on forked workers."""
    path = tmp_path_factory.mktemp("kill") / "friction.mcap"
    mi.run_experiment(mi.load_scenario(SCENARIOS / "hidden" / "friction_storey2.toml"), path)
    return path


def _diagnose(recording: Path, out: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "momentid", "diagnose", str(recording), "-o", str(out)], env=ENV,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def test_sigterm_of_diagnose_is_an_interrupt_and_leaves_no_worker(friction_recording, tmp_path):
    # On a loaded machine the workers first seen may be those of the diagnosis's last forked stage,
    # and it can finish (exit 0) before the signal lands: that attempt proves nothing, so try again
    # (three times; a diagnosis that outlives the signal, or a worker left behind, fails at once).
    for attempt in range(3):
        out = tmp_path / f"report{attempt}"
        proc = _diagnose(friction_recording, out)
        _kill_and_check(proc, _workers_of(proc, 2), signal.SIGTERM)
        if proc.returncode != 0:
            break
    err = proc.stderr.read()   # in the message: a rare exit 1 in CI (2026-12-02) left no trace to read
    assert proc.returncode == 143 and err == "error: terminated (SIGTERM)\n", (proc.returncode, err)
    assert not out.exists()   # the report folder made for it, still empty, is gone


@pytest.mark.parametrize("signalled, code, line", [("Terminated", 143, "error: terminated (SIGTERM)\n"),
                                                     ("KeyboardInterrupt", 130, "error: interrupted\n")])
def test_a_signal_after_the_command_returned_is_still_one_line(monkeypatch, capsys, signalled, code, line):
    """A signal that lands as the command returns (after its own handlers, before SIGTERM's old handler is
    back) still ends in one line and the signal's exit code, never a traceback (a rare exit 1 in CI)."""
    from momentid import cli
    from momentid.core.processes import Terminated

    raised = {"Terminated": Terminated, "KeyboardInterrupt": KeyboardInterrupt}[signalled]

    def returns_then_signalled(args):
        raise raised

    monkeypatch.setattr(cli, "_run_command", returns_then_signalled)
    assert cli.main(["identify", "lab.mcap"]) == code
    assert capsys.readouterr().err == line


@pytest.mark.slow
def test_sigkill_of_diagnose_leaves_no_worker(friction_recording, tmp_path):
    """SIGKILL cannot be handled: the workers' parent-death signal ends them (the pool test above
    checks the same in the default run, in a second)."""
    proc = _diagnose(friction_recording, tmp_path / "report")
    _kill_and_check(proc, _workers_of(proc, 2), signal.SIGKILL)


def _slow_square(x):
    time.sleep(0.2)
    return x * x


def test_a_background_job_returns_its_result_and_raises_its_error():
    from momentid.core.processes import in_background
    with in_background(lambda: _slow_square(7)) as result:
        assert result() == 49 and result() == 49   # asked twice: the same value, one job
    with in_background(lambda: 1 / 0) as result:
        with pytest.raises(ZeroDivisionError):
            result()


def test_a_background_job_not_asked_for_is_killed_when_the_block_ends():
    from momentid.core.processes import in_background
    with in_background(lambda: time.sleep(60)):
        assert len(_children(os.getpid())) >= 1
    # The speculative job is gone at once, not after its minute.
    assert not [p for p in _children(os.getpid()) if Path(f"/proc/{p}/cmdline").exists()
                and b"pytest" in Path(f"/proc/{p}/cmdline").read_bytes()]


def _borrower(task: str):
    """``short``: its pid.  ``long``: the pids of two jobs it runs with run_forked, retried until a
    core of the pool is idle (the short task's worker, with no task left) and helpers ran them."""
    from momentid.core.processes import run_forked
    if task == "short":
        return [os.getpid()]
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        pids = run_forked(lambda i: os.getpid(), [0, 1])
        if os.getpid() not in pids:
            return pids
        time.sleep(0.05)
    return [os.getpid()]


def test_a_worker_borrows_the_core_of_a_worker_with_no_task_left():
    from momentid.core import processes
    from momentid.core.processes import run_forked
    short, long = run_forked(_borrower, ["short", "long"])
    # The long task's jobs ran in helpers of its own (not in itself, not in the short task's worker)
    # once the short task's worker was idle; without a lent core they would run in the worker itself
    # and the retry loop would give up after a minute with its own pid.
    assert len(set(long)) == 2 and not set(long) & set(short) and os.getpid() not in long
    # The command lends nothing once its pool is gone.
    assert processes._IDLE is None
    with processes.helpers_allowed() as allowed:
        assert allowed   # the command itself may always start helpers


def test_a_count_includes_the_threads_and_forked_workers():
    """``counters.counting``: what the jobs add on threads and in forked workers comes back to the count;
    nothing is counted outside the block."""
    from momentid.core import counters
    from momentid.core.processes import run_forked, run_threaded

    counters.add(counters.REPLAYS, 5)   # not counting: no effect
    with counters.counting() as replays:
        run_forked(lambda n: counters.add(counters.REPLAYS, n), [1, 2, 3])
        run_threaded(lambda n: counters.add(counters.REPLAYS, n), [10, 20])
        with counters.counting() as inner:
            counters.add(counters.REPLAYS, 100)
            assert inner() == 100
        assert replays() == 136


def _square_all(xs):
    from momentid.core.processes import run_forked
    return run_forked(lambda x: x * x, xs)


def test_a_worker_of_the_callers_own_pool_runs_its_jobs_itself():
    """A daemonic process (a worker of a user's ``multiprocessing.Pool``, which may have no children)
    runs ``run_forked``'s jobs in turn instead of failing to fork; an identification called there
    forks its window refits this way."""
    import multiprocessing

    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.apply(_square_all, ([1, 2, 3],)) == [1, 4, 9]
