"""Stand-ins for failing hardware and busy machines: a disk that fills up at a given size, another
process writing the same output."""

from __future__ import annotations

import builtins
import contextlib
import errno
import os
import subprocess
import sys
from pathlib import Path


class FullDisk:
    """An open file on a disk that holds ``limit`` bytes of it: a write past that fails with ENOSPC,
    as the kernel's does (nothing of the refused write lands)."""

    def __init__(self, f, limit: int):
        self._f, self.limit = f, limit

    def write(self, data) -> int:
        if self._f.tell() + len(data) > self.limit:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return self._f.write(data)

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()


def fill_disk_at(monkeypatch, module, limit: int) -> None:
    """Every file ``module`` opens (by the builtin ``open``, or locked for writing by
    :func:`momentid.io.exclusive.open_locked`) sits on a disk that is full at ``limit`` bytes."""
    monkeypatch.setattr(module, "open", lambda *a, **k: FullDisk(builtins.open(*a, **k), limit), raising=False)
    locked = getattr(module, "open_locked", None)
    if locked is not None:
        monkeypatch.setattr(module, "open_locked", lambda path: FullDisk(locked(path), limit))


#: Another process holding an output the way momentid's writers do (``flock`` on the file, on a
#: whole-file output's ``.partial`` file, or on a folder), in plain Python: it starts in milliseconds.
_HOLDER = """
import fcntl, os, sys
kind, path = sys.argv[1], sys.argv[2]
if kind == "folder":
    os.makedirs(path, exist_ok=True)
flags = os.O_RDONLY if kind == "folder" else os.O_RDWR | os.O_CREAT
fd = os.open(path + (".partial" if kind == "whole" else ""), flags)
fcntl.flock(fd, fcntl.LOCK_EX)
print("locked", flush=True)
sys.stdin.read()            # hold until our stdin closes
"""


@contextlib.contextmanager
def held(kind: str, path: Path):
    """Another process holding ``path`` (``file``, ``whole`` or ``folder``) for the ``with`` block."""
    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, kind, str(path)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        yield holder
    finally:
        holder.stdin.close()
        holder.wait(timeout=30)
