"""Stand-ins for failing hardware: a disk that fills up at a given size."""

from __future__ import annotations

import builtins
import errno
import os


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
