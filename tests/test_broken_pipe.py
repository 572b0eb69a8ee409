"""Broken pipes are quiet (issue 22 point 6): ``momentid identify --json | head -c 10`` printed
BrokenPipeError text and exited 120; every command now stops without a word and exits 141
(128 + SIGPIPE, what a shell shows for a pipeline's writer)."""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
from pathlib import Path

import pytest

from momentid.cli import main

from bad_input.cli import THREE_RUNS, recording_bytes
from bad_input.csv_import import lab_folder

ROOT = Path(__file__).resolve().parents[1]


@contextlib.contextmanager
def reader_gone():
    """stdout is a pipe whose reader has already closed it; stderr is captured."""
    read, write = os.pipe()
    os.close(read)
    out = io.TextIOWrapper(os.fdopen(write, "wb", buffering=0), encoding="utf-8", write_through=True)
    err = io.StringIO()
    old = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = out, err
    try:
        yield err
    finally:
        sys.stdout, sys.stderr = old
        with contextlib.suppress(OSError):
            out.close()


def _setup(folder: Path) -> None:
    data, _ = recording_bytes()
    (folder / "rec.mcap").write_bytes(data)
    (folder / "s.toml").write_text(THREE_RUNS)
    (folder / "noisy.toml").write_text(THREE_RUNS + '[sensors]\nset = "accel+disp"\n[sensors.accelerometer]\n'
                                       'relative_noise = 0.01\n[sensors.displacement]\nrelative_noise = 0.01\n')
    (folder / "w.toml").write_text('[sweep]\nbase = "s.toml"\n[grid]\n"scenario.seed" = [0]\n')
    lab_folder(folder)


COMMANDS = [
    ("run", "s.toml", "-q", "-o", "out/"),
    ("identify", "rec.mcap"),
    ("identify", "rec.mcap", "--json"),
    ("identify", "rec.mcap", "--stream"),
    ("identify", "rec.mcap", "--stream", "--json"),
    ("plan", "noisy.toml"),
    ("import", "lab", "-o", "lab.mcap"),
    ("view", "rec.mcap", "--save", "v.rrd"),
    ("sweep", "w.toml", "-q", "-o", "t.csv"),
]


@pytest.mark.parametrize("argv", COMMANDS, ids=" ".join)
def test_every_command_is_quiet_when_its_reader_goes(argv, tmp_path, monkeypatch):
    _setup(tmp_path)
    monkeypatch.chdir(tmp_path)
    with reader_gone() as err:
        code = main(list(argv))
    # stderr keeps what a command says there anyway (sweep's banner), but no error and no traceback
    assert code == 141 and "rror" not in err.getvalue() and "Traceback" not in err.getvalue(), err.getvalue()


def test_the_whole_process_exits_141_without_a_word(tmp_path):
    """Also the interpreter's last flush of stdout (it wrote 'Exception ignored ... BrokenPipeError'
    and exit code 120)."""
    _setup(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "momentid", "identify", "rec.mcap", "--json"], cwd=tmp_path,
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()   # the reader is gone before the first byte (`| head -c 0`)
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 141 and err == b"", err
