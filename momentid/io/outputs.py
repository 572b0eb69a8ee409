"""The one output rule of every momentid command: never lose a file the user made.

Every command that writes (``run``, ``import``, ``view --save``, ``sweep``, ``diagnose``, ``twin``)
follows the same rule, checked here before the long work starts:

* It writes only the files it owns, each whole or not at all.
* It never deletes or overwrites a file it did not write, unless the user says ``--force``.
* A target of another kind (a folder where a file is meant, a file where a folder is meant, a text
  where a recording is meant) is refused in one line.
* It follows no symbolic link onto another file: a link at the output path is refused (``--force``
  replaces the link itself, never the file it points to).
* Errors name the path the user gave (``-o DIR``), never a temporary file.
* Writability is checked before the work, not after it.
* The command's own stale files (a plot the new result has no use for) are removed.

A single file (a recording, a ``.rrd``, a result table) is recognised as the command's own by its
contents (:data:`KINDS`).  A folder of files (a twin, a diagnosis report) keeps a small manifest,
:data:`MANIFEST`, naming each file it holds for a command with the SHA-256 of the bytes written: a
file is the command's own only while it still holds exactly those bytes, so a file the user edited
or put there under the same name is never replaced silently.  The manifest's bytes depend only on
the files, so a second identical run writes an identical folder.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from collections.abc import Callable, Iterable

from momentid.errors import OutputRefusedError
from momentid.io.exclusive import exclusive, partial_path
from momentid.io.mcap_check import MCAP_MAGIC

__all__ = ["MANIFEST", "KINDS", "check_file", "drop_link", "OwnedFolder", "OutputRefusedError"]

#: The manifest of an output folder: which command wrote which file, with the SHA-256 of its bytes.
MANIFEST = ".momentid.json"

_FORCE = "--force replaces it"


def _is_table(head: bytes) -> bool:
    """A result table of ``momentid sweep``: CSV whose first column is ``case``, or a JSON list."""
    return head.startswith(b"case,") or head.lstrip().startswith(b"[")


#: What each single-file output is, and how its first bytes are recognised.
KINDS: dict[str, tuple[str, Callable[[bytes], bool]]] = {
    "recording": ("an MCAP recording", lambda head: head.startswith(MCAP_MAGIC)),
    "rerun": ("a rerun recording (.rrd)", lambda head: head.startswith(b"RRF")),
    "table": ("a result table of `momentid sweep`", _is_table),
}


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _writable(folder: Path, option: str, shown) -> None:
    """Refuse, before any work, a folder (or the nearest one that exists above it) this process
    cannot create files in (permissions, a read-only file system)."""
    place = Path(os.path.abspath(folder))
    while not place.exists() and not place.is_symlink():
        place = place.parent
    if not place.is_dir():
        raise OutputRefusedError(option, shown, f"cannot write there: {place} is a file",
                                 "a path whose folders are folders")
    try:
        fd, probe = tempfile.mkstemp(prefix=".momentid-probe-", dir=place)
    except OSError as exc:
        raise OutputRefusedError(option, shown, f"cannot create files in {place} ({exc.strerror or exc})",
                                 "a folder this user can write") from None
    os.close(fd)
    os.unlink(probe)


def check_file(path: str | os.PathLike, kind: str, *, option: str = "-o", force: bool = False) -> Path:
    """Check, before the work, that the single-file output ``path`` may be written.

    Parameters
    ----------
    path : str or Path
        The output file the user named (or the one a command chose in a folder they named).
    kind : str
        A key of :data:`KINDS`: what the command writes there.  An existing non-empty file of
        another kind is the user's, and is refused.
    option : str
        The option the path came from, for the message.
    force : bool
        Replace a file of another kind, or a symbolic link (the link itself: see :func:`drop_link`).

    Returns
    -------
    Path

    Raises
    ------
    OutputRefusedError
        A folder stands there; a symbolic link, or a file of another kind, without ``force``;
        not a regular file; or a folder this user cannot write.
    """
    p = Path(path)
    what, recognise = KINDS[kind]
    if p.is_symlink():
        if not force:
            raise OutputRefusedError(option, path, f"a symbolic link (to {os.readlink(p)})",
                                     "a new path or a regular file: momentid follows no link onto another file "
                                     "(--force replaces the link itself, not the file it points to)")
    elif p.is_dir():
        raise OutputRefusedError(option, path, "a folder of that name exists", f"a file path for {what}")
    elif p.exists():
        if not p.is_file():
            raise OutputRefusedError(option, path, "not a regular file", f"a new path for {what}")
        if not force and p.stat().st_size > 0:
            with open(p, "rb") as f:
                head = f.read(64)
            if not recognise(head):
                other = next((desc for k, (desc, rec) in KINDS.items() if k != kind and rec(head)), None)
                found = f"an existing file, {other}, not {what}" if other else f"an existing file that is not {what}"
                raise OutputRefusedError(option, path, found, f"a new path or {what} to replace ({_FORCE})")
    _check_beside(p, kind, option, force)
    _writable(p.parent, option, path)
    return p


def _check_beside(p: Path, kind: str, option: str, force: bool) -> None:
    """The temporary file a single-file output is written to first (:func:`momentid.io.exclusive.partial_path`,
    ``rec.mcap.partial``) may be only what an earlier writer of the same kind left there (killed
    half-way), or an empty file: anything else there is the user's, refused unless ``force`` (which
    removes a link or a file there, never a folder)."""
    beside = partial_path(p)
    if not (beside.exists() or beside.is_symlink()):
        return
    what, recognise = KINDS[kind]
    folder = beside.is_dir() and not beside.is_symlink()
    if beside.is_file() and not beside.is_symlink():
        with open(beside, "rb") as f:
            head = f.read(64)
        if not head or recognise(head):
            return          # empty, or what a killed writer of this kind left: written over
    if force and not folder:
        beside.unlink()     # a link (the link itself, never the file it points to) or a file
        return
    raise OutputRefusedError(option, str(p), f"{beside} beside it is not {what} an earlier momentid left there "
                                             f"(the output is written to that path first)",
                             "no other file or folder of that name there: move it away"
                             + ("" if folder else " (--force removes it)"))


def drop_link(path: str | os.PathLike) -> None:
    """Remove a symbolic link at ``path`` (a ``--force``\\ d output), never the file it points to."""
    p = Path(path)
    if p.is_symlink():
        p.unlink()


def _read_manifest(folder: Path) -> dict:
    """The folder's manifest: file name -> {"command", "sha256"}; empty when there is none or it is
    not one (then no file counts as written by momentid)."""
    try:
        files = json.loads((folder / MANIFEST).read_text())["files"]
        return {str(k): {"command": str(v["command"]), "sha256": str(v["sha256"])} for k, v in files.items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}


class OwnedFolder:
    """An output folder a command writes its files into, never touching anyone else's.

    Parameters
    ----------
    path : str or Path
        The folder the user named (``-o DIR``); created when missing.
    command : str
        The command writing (``twin``, ``diagnose``): the owner recorded in :data:`MANIFEST`.
    option : str
        The option the folder came from, for messages.
    force : bool
        Overwrite files of these names that the command did not write.
    """

    def __init__(self, path, command: str, *, option: str = "-o", force: bool = False):
        self.path, self.command, self.option, self.force = Path(path), command, option, force

    def _refuse(self, found: str, expected: str) -> OutputRefusedError:
        return OutputRefusedError(self.option, str(self.path), found, expected)

    def _mine(self, name: str, manifest: dict) -> bool:
        """Whether ``name`` in the folder is this command's: listed for it, with the bytes it wrote."""
        p = self.path / name
        entry = manifest.get(name)
        return (entry is not None and entry["command"] == self.command and p.is_file() and not p.is_symlink()
                and _sha256(p) == entry["sha256"])

    def _foreign(self, names: Iterable[str], manifest: dict) -> list[str]:
        return [n for n in names if ((self.path / n).exists() or (self.path / n).is_symlink())
                and not self._mine(n, manifest)]

    def _refuse_foreign(self, foreign: list[str], manifest: dict) -> None:
        folders = [n for n in foreign if (self.path / n).is_dir() and not (self.path / n).is_symlink()]
        if folders:     # --force replaces files, never a folder (and what it holds)
            raise self._refuse(f"the folder holds a folder {folders[0]}, where `momentid {self.command}` writes a "
                               f"file", "no folder of that name in it: move it away (--force replaces files, "
                                        "never folders)")
        if not foreign or self.force:
            return
        name = foreign[0]
        more = f" (and {len(foreign) - 1} more)" if len(foreign) > 1 else ""
        if not (self.path / MANIFEST).exists():    # written before momentid kept one, or by hand
            raise self._refuse(f"the folder holds {name}{more}, which `momentid {self.command}` would overwrite, "
                               f"and no {MANIFEST}, the list of the files momentid wrote there (a folder written "
                               f"by momentid before it kept that list, or files of yours: it cannot tell which)",
                               "a new folder, or --force to overwrite these files once you know they are not "
                               "yours (the folder keeps the list from then on)")
        owner = manifest.get(name, {}).get("command")
        whose = (f"`momentid {owner}` wrote it" if owner and owner != self.command
                 else "it was changed since momentid wrote it" if owner
                 else "momentid did not write it")
        raise self._refuse(f"the folder holds {name}{more}, which `momentid {self.command}` would overwrite, "
                           f"but {whose}", "a new or empty folder, or one this command wrote before "
                                           "(--force overwrites such files)")

    def check(self, names: Iterable[str] = ()) -> None:
        """Before the work: the folder can be made and written, and holds no file of ``names`` that is
        not this command's (the names it may write; those it writes are checked again at the end).

        Raises
        ------
        OutputRefusedError
        """
        p = self.path
        if p.exists() and not p.is_dir():
            raise self._refuse("a file of that name exists", "a folder (or a new path)")
        _writable(p, self.option, str(p))
        if p.is_dir():
            manifest = _read_manifest(p)
            self._refuse_foreign(self._foreign(names, manifest), manifest)

    def write(self, build: Callable[[Path], Iterable[str]]) -> list[str]:
        """Build the command's files in a private folder inside ``path``, then put each in place.

        ``build(staging)`` writes its files into ``staging`` and returns their names.  Only when all
        are built is any file in ``path`` touched: each is renamed into place (whole), the command's
        files of a previous run that this one did not write again are removed, and the manifest is
        updated.  An error or interrupt while building leaves ``path`` as it was.

        Returns
        -------
        list of str
            The names written, in ``build``'s order.

        Raises
        ------
        OutputRefusedError
            See :meth:`check`; or the files could not be written (the message names ``path``).
        OutputBusyError
            Another process is writing the folder.
        """
        self.check()
        with exclusive(self.path):
            staging = Path(tempfile.mkdtemp(prefix=".momentid-", suffix=".partial", dir=self.path))
            try:
                try:
                    names = list(build(staging))
                except OSError as exc:
                    raise self._refuse(f"cannot write the {self.command} files ({exc.strerror or exc}); the "
                                       "folder was left as it was", "a folder with room that this user can write"
                                       ) from None
                if any(Path(n).name != n or n in ("", ".", "..", MANIFEST) for n in names):
                    raise ValueError(f"file names {names!r}: expected plain names")   # a bug, not a user's
                manifest = _read_manifest(self.path)
                self._refuse_foreign(self._foreign(names, manifest), manifest)
                self._place(staging, names, manifest)
            finally:
                shutil.rmtree(staging, ignore_errors=True)
        return names

    def _place(self, staging: Path, names: list[str], manifest: dict) -> None:
        stale = [n for n, e in manifest.items() if e["command"] == self.command and n not in names
                 and self._mine(n, manifest)]
        written = {n: {"command": self.command, "sha256": _sha256(staging / n)} for n in names}
        for name in names:
            try:
                os.replace(staging / name, self.path / name)
            except OSError as exc:
                raise self._refuse(f"cannot put {name} in place ({exc.strerror or exc})",
                                   "a folder this user can write, holding no folder of that name") from None
        for name in stale:
            with contextlib.suppress(FileNotFoundError):
                (self.path / name).unlink()
        kept = {n: e for n, e in manifest.items() if n not in written and n not in stale
                and (self.path / n).exists()}
        files = dict(sorted({**kept, **written}.items()))
        text = json.dumps({"written_by": "momentid", "files": files}, indent=1, sort_keys=True) + "\n"
        temp = staging / MANIFEST
        temp.write_text(text)
        os.replace(temp, self.path / MANIFEST)
