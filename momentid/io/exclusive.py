"""One writer per output: an exclusive lock (``fcntl.flock``) on whatever momentid writes.

Two processes writing the same recording at once each truncate it and interleave their bytes: the
file left is unreadable, and both used to report success.  Every writer takes the lock before it
changes a byte; a second writer gets one line naming the output (:class:`OutputBusyError`) and
the first finishes undisturbed.

* A file written in place (a recording, run by run, so that a crash keeps the completed runs):
  the lock is on the file itself, taken before it is truncated (:func:`open_locked`).
* A file written whole or not at all (a ``.rrd``, a table): the lock is on its temporary file,
  which is renamed into place while the lock is held (:func:`reserve`, :func:`write_whole`).
* A folder of files (a diagnosis report): the lock is on the folder (:func:`exclusive`).

A lock dies with its process (even on SIGKILL), so no stale lock is left to clean up; within one
process the same output may be locked again (a command locks its report folder up front, the
writer locks it again).  Where ``flock`` does not exist (not POSIX) or a file system refuses it
(some network mounts), writing goes on unlocked: the lock protects, it never blocks a write it
cannot protect.
"""

from __future__ import annotations

import contextlib
import errno
import os
from pathlib import Path
from typing import BinaryIO
from collections.abc import Iterator

from momentid.errors import OutputBusyError

try:   # POSIX; elsewhere writing goes on unlocked (see the module docstring)
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None

__all__ = ["OutputBusyError", "busy_error", "open_locked", "exclusive", "reserve", "write_whole", "partial_path"]

#: Outputs this process holds (resolved path -> nesting depth): locking one again is a no-op.
_HELD: dict[str, int] = {}
#: Attempts to lock a path that another process keeps replacing (renaming a new file into place).
_ATTEMPTS = 5


def busy_error(path: Path) -> OutputBusyError:
    """The one line for an output ``path`` (the one the user gave) another process is writing."""
    return OutputBusyError(f"{path}: another process is writing it now; expected one writer per output: "
                           "wait for it to finish or choose another output path")


def _flock(fd: int, path: Path) -> None:
    """Lock ``fd`` exclusively without waiting; a lock held elsewhere is :class:`OutputBusyError`."""
    if fcntl is None:
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            raise busy_error(path) from None
        # ENOLCK, EOPNOTSUPP, EINVAL: the file system has no locks; write unlocked


def _locked_fd(path: Path, flags: int) -> int:
    """Open ``path`` with ``flags`` and lock it; the path must still name the locked file afterwards
    (another writer may have renamed a new file into place meanwhile: then lock that one)."""
    for _ in range(_ATTEMPTS):
        fd = os.open(path, flags | getattr(os, "O_CLOEXEC", 0), 0o666)
        try:
            _flock(fd, path)
            mine, now = os.fstat(fd), os.stat(path)
        except FileNotFoundError:
            os.close(fd)
            continue
        except BaseException:
            os.close(fd)
            raise
        if (mine.st_dev, mine.st_ino) == (now.st_dev, now.st_ino):
            return fd
        os.close(fd)
    raise busy_error(path)


def open_locked(path: str | os.PathLike) -> BinaryIO:
    """Open ``path`` for writing in place, locked for this process, truncated only once locked.

    Returns a binary file object; closing it releases the lock.

    Raises
    ------
    OutputBusyError
        Another process holds the file (it is left untouched).
    OSError
        The file cannot be created (no folder, no permission).
    """
    path = Path(path)
    # O_NOFOLLOW: a symbolic link at an output file is never followed onto the file it points to
    fd = _locked_fd(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0))
    try:
        os.ftruncate(fd, 0)
        return os.fdopen(fd, "wb")
    except BaseException:
        os.close(fd)
        raise


@contextlib.contextmanager
def exclusive(path: str | os.PathLike) -> Iterator[Path]:
    """Hold ``path`` (a folder, created if missing and removed again if the block fails while it is
    still empty; or an existing file) for the ``with`` block.

    Raises
    ------
    OutputBusyError
        Another process holds it.
    """
    path = Path(path)
    key = os.path.realpath(path)
    if key in _HELD:
        _HELD[key] += 1
        try:
            yield path
        finally:
            _HELD[key] -= 1
        return
    created = not path.exists()
    if created:
        path.mkdir(parents=True)
    fd = _locked_fd(path, os.O_RDONLY)
    _HELD[key] = 1
    try:
        yield path
    except BaseException:
        if created:   # a folder made for output that never came: leave no empty folder behind
            with contextlib.suppress(OSError):
                path.rmdir()
        raise
    finally:
        del _HELD[key]
        os.close(fd)


def partial_path(path: str | os.PathLike) -> Path:
    """The temporary file ``path`` is written to before it is renamed into place."""
    path = Path(path)
    return path.with_name(path.name + ".partial")


class _Slot:
    """The locked temporary file of :func:`reserve`; :meth:`commit` puts the bytes in place."""

    def __init__(self, path: Path, file: BinaryIO):
        self.path, self._file = path, file

    def commit(self, data: bytes) -> Path:
        """Write ``data`` to the temporary file, make it durable and rename it to the output."""
        self._file.write(data)
        self._file.flush()
        os.fsync(self._file.fileno())
        os.replace(partial_path(self.path), self.path)
        return self.path


@contextlib.contextmanager
def reserve(path: str | os.PathLike) -> Iterator[_Slot]:
    """Lock the output ``path`` now (its temporary file) and write it whole later with ``commit``.

    For a command that computes for minutes before it writes: a second writer is refused at once,
    not at the end.  Leaving the block without ``commit`` (an error, Ctrl-C) removes the temporary
    file and leaves ``path`` as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temp = partial_path(path)
    try:
        file = open_locked(temp)
    except OutputBusyError:
        raise busy_error(path) from None   # name the output the user gave, not its temporary file
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    try:
        yield _Slot(path, file)
    finally:
        with contextlib.suppress(OSError):   # not committed: the temporary file goes, if still ours
            mine, now = os.fstat(file.fileno()), os.stat(temp)
            if (mine.st_dev, mine.st_ino) == (now.st_dev, now.st_ino):
                temp.unlink()
        file.close()


def write_whole(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` whole or not at all, locked (see :func:`reserve`)."""
    with reserve(path) as slot:
        return slot.commit(data)
