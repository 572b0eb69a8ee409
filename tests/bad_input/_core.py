"""The bad-input suite's machinery: a case is data (an input, an action, the outcome class it must
end in); :func:`observe` runs it and :func:`check` says whether the outcome is the promised one.

Outcome classes (docs/reliability.md):

* ``ERROR``: one line, a :class:`~momentid.errors.MomentidError` (or, at the command line,
  ``error: ...`` on stderr and exit code 2) whose message names the file, key or value at fault;
* ``RECOVERY``: the work completes with what could be saved, and a note says what was lost;
* ``REFUSAL``: a well-formed input asks for work that would be wrong or would not fit, and it is
  refused before it starts (a one-line error saying why and what would do).

Anything else (a traceback, any other exception, a silent success on damaged input) fails.
"""

from __future__ import annotations

import contextlib
import enum
from collections import Counter
import io
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Callable

from momentid.errors import IdentificationError, MomentidError, ResourceError


class Outcome(enum.Enum):
    """The outcome class a case must end in."""

    ERROR = "one-line error naming file/key/value"
    RECOVERY = "recovery with a note"
    REFUSAL = "refusal before the work starts"


class Group(enum.Enum):
    """The entry point a case feeds."""

    SCENARIO = "scenario TOML"
    AT2 = "AT2 record"
    CSV = "CSV import"
    IMU = "IMU import (Xsens DOT)"
    RECORDING = "recording (MCAP)"
    CLI = "CLI paths and options"


#: Exception classes that make an error a refusal of well-formed work rather than a bad input.
REFUSALS = (ResourceError, IdentificationError)


@dataclass(frozen=True)
class CliResult:
    """What ``momentid.cli.main`` returned and printed."""

    code: int
    stdout: str
    stderr: str


@dataclass(frozen=True)
class Case:
    """One bad input.

    ``act(folder)`` builds the input inside the empty ``folder`` and feeds it to the entry point; it
    returns the result (an object with ``notes``, or a :class:`CliResult`) or raises.  ``names``
    must all appear in the message (file, key, value: what the user needs to find the fault).
    ``xfail`` names the module and change a known defect needs (strict: it must still fail).
    """

    group: Group
    id: str
    outcome: Outcome
    act: Callable[[Path], object]
    names: tuple[str, ...] = ()
    xfail: str | None = None


@dataclass(frozen=True)
class Observed:
    """How a case ended: ``kind`` is ``error``, ``refusal``, ``note``, ``ok`` or ``crash``."""

    kind: str
    message: str
    lines: int = 1
    details: dict = field(default_factory=dict)


def cli(*argv: str) -> CliResult:
    """Run the command line in this process and capture what it prints."""
    from momentid.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse's own usage errors
            code = exc.code if isinstance(exc.code, int) else 2
    return CliResult(code, out.getvalue(), err.getvalue())


def _observe_cli(result: CliResult) -> Observed:
    err = result.stderr
    if "Traceback" in err or "Traceback" in result.stdout:
        return Observed("crash", err)
    errors = [line for line in err.splitlines() if "error: " in line]
    if result.code != 0:
        kind = "crash" if result.code != 2 or len(errors) != 1 else "refusal" if "refused" in errors[0] else "error"
        return Observed(kind, errors[0] if errors else err, lines=len(errors))
    notes = [line for line in err.splitlines() if line.startswith(("note: ", "WARNING", "warning: "))]
    return Observed("note" if notes else "ok", "\n".join(notes) or result.stdout[-300:])


def observe(case: Case, folder: Path) -> Observed:
    """Run ``case`` in ``folder`` (empty, writable; the current directory meanwhile)."""
    here = os.getcwd()
    os.chdir(folder)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # notes are checked in the result, not on stderr
            result = case.act(folder)
    except REFUSALS as exc:
        return Observed("refusal", str(exc), lines=len(str(exc).splitlines()))
    except MomentidError as exc:
        return Observed("error", str(exc), lines=len(str(exc).splitlines()))
    except Exception as exc:  # noqa: BLE001  (the suite's job: any other exception is a crash)
        return Observed("crash", f"{type(exc).__name__}: {exc}")
    finally:
        os.chdir(here)
    if isinstance(result, CliResult):
        return _observe_cli(result)
    notes = tuple(getattr(result, "notes", ()) or ())
    return Observed("note" if notes else "ok", "\n".join(notes))


#: The observed kinds each outcome class accepts.
_ACCEPTS = {Outcome.ERROR: ("error",), Outcome.RECOVERY: ("note",), Outcome.REFUSAL: ("refusal",)}


def check(case: Case, seen: Observed) -> str | None:
    """None when ``seen`` is the outcome ``case`` promises, else what is wrong (one line)."""
    if seen.kind not in _ACCEPTS[case.outcome]:
        return f"expected {case.outcome.value}, got {seen.kind}: {seen.message[:400]}"
    if seen.kind in ("error", "refusal") and seen.lines != 1:
        return f"expected a one-line message, got {seen.lines} lines: {seen.message[:400]}"
    missing = [n for n in case.names if n not in seen.message]
    if missing:
        return f"the message does not name {missing}: {seen.message[:400]}"
    return None


#: The columns of the summary table: the three outcome classes, then the known defects (xfail).
KNOWN_DEFECT = "known defect"


def promised(cases) -> Counter:
    """Cases per (entry point, outcome class or :data:`KNOWN_DEFECT`), as the tables promise them."""
    return Counter((c.group, KNOWN_DEFECT if c.xfail else c.outcome) for c in cases)


def table(counts: Counter) -> list[str]:
    """The Markdown table of ``counts`` (docs/reliability.md pastes it)."""
    columns = [*Outcome, KNOWN_DEFECT]
    names = [c.name.lower() if isinstance(c, Outcome) else c for c in columns]
    lines = [f"| entry point | {' | '.join(names)} | cases |", "|---" * (len(columns) + 2) + "|"]
    for group in Group:
        row = [counts[group, c] for c in columns]
        lines.append(f"| {group.value} | {' | '.join(map(str, row))} | {sum(row)} |")
    totals = [sum(counts[g, c] for g in Group) for c in columns]
    lines.append(f"| all | {' | '.join(map(str, totals))} | {sum(totals)} |")
    return lines
