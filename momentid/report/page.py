"""One self-contained HTML page per result (``report.html``): the answer, tables, figures, provenance.

:class:`Page` collects a result's sections and writes them in this order whatever order they were
added in:

1. **the answer** (the result's summary block, the words of its ``_repr_html_``);
2. **tables** with units;
3. **figures**, drawn as inline SVG (no file beside the page, no network, readable in print); a
   figure that cannot be drawn becomes a note in its place: writing a page never fails the command;
4. **how it was made** (:class:`Provenance`): the exact command, the versions of momentid, MuJoCo and
   the numerical libraries, and each input file's SHA-256.

The page loads nothing: a Content-Security-Policy forbids every request except the page's own
inline styles and ``data:`` images, and there is no script.  Everything put in it is escaped
(:func:`momentid.core.html.escape`).  The same result gives the same bytes: no timestamp, no random
identifier (:func:`momentid.report.figures.svg`).
"""

from __future__ import annotations

import hashlib
import os
import platform
import shlex
import tempfile
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from momentid.core import html
from momentid.core.html import escape

__all__ = ["Page", "Provenance", "provenance", "sha256", "write_text_atomic", "missing_note", "CSP"]

#: Nothing is loaded: no script, no request; inline styles and ``data:`` images (SVG may embed them).
CSP = "default-src 'none'; style-src 'unsafe-inline'; img-src data:"

_CSS = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 75em; padding: 0 1em; color: #111; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { border-bottom: 2px solid #333; padding-bottom: 0.1em; margin-top: 1.6em; }
h3 { margin: 1.2em 0 0.3em; font-size: 1.05em; }
nav { color: #555; font-size: 0.9em; }
nav a { color: #1a4d8f; }
table { border-collapse: collapse; margin: 0.4em 0 1em; }
th, td { border-bottom: 1px solid #ccc; padding: 0.15em 0.6em; text-align: right;
  font-variant-numeric: tabular-nums; vertical-align: top; }
td { white-space: nowrap; }
td.name { white-space: normal; }
section { overflow-x: auto; }
th { background: #f2f2f2; }
td.name, th.name { text-align: left; }
caption { text-align: left; font-weight: 600; padding: 0.2em 0; }
figure { margin: 1em 0 2em; }
figure svg { width: 100%; height: auto; max-width: 72em; display: block; }
figcaption { color: #333; font-size: 0.92em; margin-top: 0.3em; }
.note { color: #555; }
.figure-missing { color: #8a1c00; border: 1px dashed #c0392b; padding: 0.5em; }
dl.provenance dt { font-weight: 600; margin-top: 0.4em; }
dl.provenance dd { margin-left: 1.5em; font-family: ui-monospace, monospace; overflow-wrap: anywhere; }
@media print {
  body { max-width: none; margin: 0; }
  figure, table { break-inside: avoid; }
  nav { display: none; }
}
"""


@dataclass(frozen=True)
class Provenance:
    """How a result was made.

    Attributes
    ----------
    command : str or None
        The exact command line (None: made through the Python API).
    inputs : tuple of (str, str or None)
        Each input file as named and its SHA-256 (hex; None: not a file, an experiment in memory).
    versions : tuple of (str, str)
        Package and version: momentid, MuJoCo, Python, NumPy, SciPy, matplotlib.
    """

    command: str | None
    inputs: tuple
    versions: tuple


def sha256(path: str | os.PathLike) -> str:
    """The SHA-256 (hex) of the file at ``path``, read in blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _versions() -> tuple:
    import matplotlib
    import mujoco
    import numpy
    import scipy

    from momentid.core.version import __version__

    return (("momentid", __version__), ("MuJoCo", mujoco.__version__), ("Python", platform.python_version()),
            ("NumPy", numpy.__version__), ("SciPy", scipy.__version__), ("matplotlib", matplotlib.__version__))


def provenance(argv: Sequence[str] | None, inputs: Sequence) -> Provenance:
    """The provenance of a result made by ``momentid ARGV`` (None: by the Python API) from ``inputs``
    (paths; a name that is no file, such as ``<memory>``, is listed without a hash)."""
    hashed = []
    for name in inputs:
        try:
            hashed.append((str(name), sha256(name) if Path(name).is_file() else None))
        except OSError:
            hashed.append((str(name), None))
    command = None if argv is None else "momentid " + shlex.join(list(argv))
    return Provenance(command, tuple(hashed), _versions())


class Page:
    """A report page under construction (module docstring).

    Parameters
    ----------
    title : str
        The page's title and first heading (text).
    lead : str
        One line under the title (text): what the result is of.
    made : Provenance
    """

    def __init__(self, title: str, lead: str, made: Provenance):
        self.title, self.lead, self.made = title, lead, made
        self._answer: list[str] = []
        self._tables: list[str] = []
        self._figures: list[str] = []
        self._count = 0

    def answer(self, fragment: str) -> None:
        """Add HTML (made by :mod:`momentid.core.html`) to the answer section."""
        self._answer.append(fragment)

    def table(self, heading: str, fragment: str, note: str = "") -> None:
        """Add a table (:func:`momentid.core.html.table`) under ``heading`` (text), with a ``note``
        (text) under it."""
        extra = f'<p class="note">{escape(note)}</p>\n' if note else ""
        self._tables.append(f"<h3>{escape(heading)}</h3>\n{fragment}{extra}")

    def lines(self, heading: str, lines: Sequence[str]) -> None:
        """Add lines of words (notes, warnings: :func:`momentid.core.html.word_lines`) to the tables section."""
        if lines:
            self._tables.append(f'<h3>{escape(heading)}</h3>\n<div class="momentid-summary">'
                                f"{html.word_lines(lines)}</div>\n")

    def section(self, heading: str, build: Callable[[], str]) -> None:
        """Add a table built by ``build`` (HTML); if it fails, a note saying so takes its place."""
        try:
            self._tables.append(f"<h3>{escape(heading)}</h3>\n{build()}")
        except Exception as exc:   # a report never fails the command: the reason goes on the page
            self._tables.append(f"<h3>{escape(heading)}</h3>\n{missing_note('this table', exc)}")

    def figure(self, caption: str, build: Callable[[], object]) -> None:
        """Draw the matplotlib figure ``build()`` returns as inline SVG with ``caption`` (text); a figure
        that cannot be drawn becomes a note naming the error."""
        from momentid.report.figures import svg

        self._count += 1
        try:
            drawing = svg(build(), self._count)
        except Exception as exc:   # a report never fails the command: the reason goes on the page
            self._figures.append(f"<figure>{missing_note(f'figure {self._count}', exc)}"
                                 f"<figcaption>Figure {self._count}. {escape(caption)}</figcaption></figure>\n")
            return
        self._figures.append(f'<figure id="figure-{self._count}">\n{drawing}\n'
                             f"<figcaption>Figure {self._count}. {escape(caption)}</figcaption></figure>\n")

    def html(self) -> str:
        """The whole page."""
        made = self.made
        inputs = "".join(f"<dd>{escape(name)}<br>SHA-256 {escape(digest) if digest else '(not a file)'}</dd>"
                         for name, digest in made.inputs) or "<dd>(none)</dd>"
        versions = ", ".join(f"{escape(k)} {escape(v)}" for k, v in made.versions)
        command = escape(made.command) if made.command else "(made through the Python API, not the command line)"
        sections = [("answer", "The answer", "".join(self._answer)),
                    ("tables", "Tables", "".join(self._tables) or '<p class="note">No tables.</p>'),
                    ("figures", "Figures", "".join(self._figures) or '<p class="note">No figures.</p>'),
                    ("made", "How it was made",
                     f'<dl class="provenance"><dt>Command</dt><dd>{command}</dd><dt>Input</dt>{inputs}'
                     f"<dt>Versions</dt><dd>{versions}</dd></dl>\n")]
        nav = " · ".join(f'<a href="#{key}">{escape(name)}</a>' for key, name, _ in sections)
        body = "".join(f'<section id="{key}">\n<h2>{escape(name)}</h2>\n{content}</section>\n'
                       for key, name, content in sections)
        version = dict(made.versions).get("momentid", "")
        return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
                f'<meta http-equiv="Content-Security-Policy" content="{CSP}">\n'
                f'<meta name="viewport" content="width=device-width, initial-scale=1">\n'
                f'<meta name="generator" content="momentid {escape(version)}">\n'
                f"<title>{escape(self.title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n"
                f"<header><h1>{escape(self.title)}</h1>\n<p>{escape(self.lead)}</p>\n<nav>{nav}</nav></header>\n"
                f"{body}</body>\n</html>\n")


def missing_note(what: str, exc: BaseException) -> str:
    """The note that takes the place of a table or figure that could not be made."""
    where = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    at = f" (in {Path(where.filename).name}, line {where.lineno})" if where else ""
    return (f'<p class="figure-missing">{escape(what.capitalize())} could not be drawn: '
            f"{escape(type(exc).__name__)}: {escape(exc)}{escape(at)}.</p>")


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file beside it, renamed into place: a
    reader never sees half a file, and an error leaves any previous file as it was."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as f:
            f.write(text)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
