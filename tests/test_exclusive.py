"""One writer per output (issue 22 point 4): a second writer of the same file or folder is refused
with one line naming it, and the first finishes intact."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from momentid.cli import main
from momentid.errors import OutputBusyError
from momentid.io.exclusive import exclusive, open_locked, partial_path, reserve, write_whole
from momentid.io.recording import read_recording

from bad_input.faults import held

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}

#: The default scenario lengthened to 180 s: a run long enough (about 10 s on one worker) that a second
#: command starts while the first is still writing (at 60 s, about 3.5 s, the first finished first now
#: and then: a second command takes 1-2 s to start).
LONG = (ROOT / "momentid" / "lab" / "default_scenario.toml").read_text().replace(
    "duration = 10.0 ", "duration = 180.0 ")

def _cli(capsys, *argv) -> tuple[int, str]:
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


@pytest.mark.slow   # 10 s of two processes; the lock itself is tested in this process below
def test_two_runs_writing_the_same_recording(tmp_path):
    """Two `momentid run -o same.mcap` at once: the second is refused with one line, the first
    finishes and its recording reads back whole."""
    scenario = tmp_path / "long.toml"
    scenario.write_text(LONG)
    out = tmp_path / "same.mcap"
    argv = [sys.executable, "-m", "momentid", "run", str(scenario), "-q", "-j", "1", "-o", str(out)]
    first = subprocess.Popen(argv, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not (out.exists() and out.stat().st_size > 0):   # the header is written under the lock
            assert first.poll() is None and time.monotonic() < deadline, first.stderr.read() if first.poll() else ""
            time.sleep(0.02)
        second = subprocess.run(argv, env=ENV, capture_output=True, text=True, timeout=120)
    finally:
        _, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    # (a second run that succeeds started after the first had finished: LONG would need lengthening)
    assert second.returncode == 2 and second.stderr.count("\n") == 1, second.stderr
    assert second.stderr.startswith("error: ") and str(out) in second.stderr, second.stderr
    experiment = read_recording(out)
    assert experiment.complete and [r.name for r in experiment.runs] == ["reference", "uniform", "ends"]


def test_a_held_file_is_neither_truncated_nor_written(tmp_path):
    path = tmp_path / "rec.mcap"
    path.write_bytes(b"first writer's bytes")
    with held("file", path), pytest.raises(OutputBusyError, match="rec.mcap"):
        open_locked(path)
    assert path.read_bytes() == b"first writer's bytes"
    with open_locked(path) as f:   # free again once the holder is gone
        f.write(b"second")
    assert path.read_bytes() == b"second"


def test_sweep_refused_before_it_starts_while_another_process_writes_its_table(tmp_path, capsys):
    table = tmp_path / "t.csv"
    spec = tmp_path / "w.toml"
    spec.write_text(f'[sweep]\nbase = "{ROOT / "scenarios" / "default.toml"}"\n[grid]\n"scenario.seed" = [0]\n')
    with held("whole", table):
        code, err = _cli(capsys, "sweep", spec, "-o", table, "-q")
    assert code == 2 and str(table) in err and err.count("\n") == 1, err
    assert not table.exists()


def test_view_save_refused_while_another_process_writes_the_file(tmp_path, capsys, simulated):
    from momentid.io.recording import write_experiment

    rec = write_experiment(tmp_path / "rec.mcap", simulated("default", ideal=True))
    rrd = tmp_path / "v.rrd"
    rrd.write_bytes(b"old")
    with held("whole", rrd):
        code, err = _cli(capsys, "view", rec, "--save", rrd)
    assert code == 2 and str(rrd) in err and err.count("\n") == 1, err
    assert rrd.read_bytes() == b"old"   # the holder's output is not disturbed


def test_diagnose_refused_while_another_process_writes_its_folder(tmp_path, capsys, simulated):
    from momentid.io.recording import write_experiment

    rec = write_experiment(tmp_path / "rec.mcap", simulated("default", ideal=True))
    folder = tmp_path / "report"
    with held("folder", folder):
        code, err = _cli(capsys, "diagnose", rec, "-o", folder)
    assert code == 2 and str(folder) in err and err.count("\n") == 1, err
    assert list(folder.iterdir()) == []


def test_reserve_commits_whole_or_leaves_the_old_file(tmp_path):
    path = tmp_path / "t.json"
    path.write_text("old")
    with pytest.raises(KeyboardInterrupt), reserve(path):
        raise KeyboardInterrupt
    assert path.read_text() == "old" and not partial_path(path).exists()
    write_whole(path, b"new")
    assert path.read_text() == "new" and not partial_path(path).exists()


def test_the_same_process_may_lock_a_folder_again(tmp_path):
    with exclusive(tmp_path / "f"), exclusive(tmp_path / "f"):
        (tmp_path / "f" / "x").write_text("x")
    with held("folder", tmp_path / "f"):
        with pytest.raises(OutputBusyError):
            with exclusive(tmp_path / "f"):
                pass


def test_a_folder_made_for_output_that_never_came_is_removed(tmp_path):
    with pytest.raises(ValueError), exclusive(tmp_path / "new"):
        raise ValueError
    assert not (tmp_path / "new").exists()
