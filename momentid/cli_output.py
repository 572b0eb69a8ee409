"""Where the ``momentid`` command writes: ``-o`` paths and folders, and a stdout kept to one JSON object.

Used by :mod:`momentid.cli`; every refusal is an :class:`OutputError` (a
:class:`~momentid.errors.MomentidError`) naming the ``-o`` value and what was expected.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterator
import contextlib
import io
import os
import sys
from pathlib import Path
from typing import Any, TYPE_CHECKING

from momentid.errors import MomentidError

if TYPE_CHECKING:
    from momentid.core.series import Experiment
    from momentid.estimation.identified import Identification
    from momentid.estimation.scaled import ModalIdentification
    from momentid.report.page import Provenance

__all__ = ["OutputError", "output_path", "output_folder", "replaced", "only_json_on_stdout", "report_page",
           "identification_output", "write_identification_folder", "refuse_empty_paths"]


#: Options that name a path to write; an empty value is refused (:func:`refuse_empty_paths`).
PATH_OPTIONS = (("output", "-o"), ("save", "--save"))


def refuse_empty_paths(args: argparse.Namespace) -> None:
    """Refuse an empty output path (``-o ""``, ``--save ""``: an unset shell variable, say), which would
    mean the current folder, the default one, or no output at all depending on the command."""
    for key, option in PATH_OPTIONS:
        value = getattr(args, key, None)
        if value is not None and not value.strip():
            raise OutputError(repr(value), f"an empty path (an unset shell variable?); expected a file or folder "
                                           f"path, or no {option} for the command's default", option=option)


def output_path(out: str | None, name: str, *, force: bool = False) -> Path:
    """The recording ``-o`` names: a ``.mcap`` path, or a folder to hold ``<name>.mcap``; checked
    before the work under the one output rule (:func:`momentid.io.outputs.check_file`): a folder, a
    symbolic link or a file that is not a recording there is refused (the last two unless ``force``)."""
    from momentid.io.outputs import check_file

    p = Path("out") / f"{name}.mcap" if out is None else Path(out)
    if p.suffix != ".mcap":
        p = output_folder(out) / f"{name}.mcap"
    if p.is_dir():
        raise OutputError(str(p), "a folder of that name exists; expected a .mcap file path")
    return check_file(p, "recording", force=force)


def replaced(out: Path, existed: bool) -> None:
    """An existing recording at ``-o`` is replaced once written (it can be made again: the same
    scenario and seed, the same lab folder), and said so."""
    if existed:
        print(f"note: {out}: an existing file, replaced by this recording", file=sys.stderr)


class OutputError(MomentidError):
    def __init__(self, out: str, expected: str, option: str = "-o"):
        self.out = out
        super().__init__(f"{option} {out}: {expected}")


def output_folder(out: str | os.PathLike) -> Path:
    """``-o`` as a folder to write into: refused when a file stands there."""
    p = Path(out)
    if p.exists() and not p.is_dir():
        raise OutputError(out, "a file of that name exists; expected a folder (or a new path)")
    return p


@contextlib.contextmanager
def only_json_on_stdout(active: bool) -> Iterator[None]:
    """Context manager: with ``active`` (``--json``), stdout carries exactly one JSON object: anything
    native code writes to file descriptor 1 (LAPACK's ``** On entry to ...`` lines, say) goes to
    stderr instead; Python's ``print`` still reaches stdout.  Inactive, or when stdout is not file
    descriptor 1 (captured), it changes nothing."""
    try:
        fd = sys.stdout.fileno() if active else -1
    except (AttributeError, OSError, io.UnsupportedOperation):  # captured or replaced stdout
        fd = -1
    if fd != 1:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    old = sys.stdout
    sys.stdout = io.TextIOWrapper(os.fdopen(os.dup(saved), "wb"), encoding="utf-8", line_buffering=True)
    try:
        yield
    finally:
        sys.stdout.flush()
        sys.stdout.close()
        sys.stdout = old
        os.dup2(saved, 1)
        os.close(saved)


def identification_output(args: argparse.Namespace) -> Path | None:
    """``identify -o DIR``: the folder, checked under the one output rule before the work
    (:func:`momentid.report.files.identification_folder`); None without ``-o``."""
    from momentid.report.files import IDENTIFICATION_FILES, identification_folder

    if not args.output:
        return None
    out = output_folder(args.output)
    identification_folder(out, force=args.force).check(IDENTIFICATION_FILES)
    return out


def write_identification_folder(out: Path,
                                result: Identification | ModalIdentification | tuple[ModalIdentification, ...],
                                experiment: Experiment, payload: dict, args: argparse.Namespace, **extra: Any) -> None:
    """``identify -o DIR``: the folder, and one line naming what it holds (stderr with ``--json``); ``extra``:
    :func:`momentid.report.files.write_identification`'s ``comparison`` or ``trend``."""
    from momentid.report.files import write_identification
    from momentid.report.page import provenance

    made = provenance(getattr(args, "argv", None), [args.recording])
    names = write_identification(out, result, experiment, payload, made, force=args.force, **extra)
    print(f"\nreport written to {out}/ ({', '.join(names)})", file=sys.stderr if args.json else sys.stdout)


def report_page(out: Path, page: Callable[[Provenance], str], args: argparse.Namespace) -> str:
    """Write ``out/report.html``, ``page(provenance)``'s HTML; returns its name."""
    from momentid.report.files import REPORT_HTML
    from momentid.report.page import provenance, write_text_atomic

    write_text_atomic(out / REPORT_HTML, page(provenance(getattr(args, "argv", None), [args.recording])))
    return REPORT_HTML
