"""PEER AT2 accelerograms: the reader of a scenario's ``[excitation] type = "record"`` file.

The layout is free-text header lines, a line giving the number of points and the sample interval,
then the values in g (any number per line).  Every malformed file is a
:class:`~momentid.errors.ScenarioError` naming the file, the line and the token.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np

from momentid.errors import ScenarioError

__all__ = ["read_at2", "MAX_RECORD_G"]

#: Largest acceleration magnitude (g) a record may hold. The strongest ground motions recorded
#: reach a few g; 100 g leaves room for any shake-table or scaled record while refusing values
#: that only a unit mistake or a damaged file produces.
MAX_RECORD_G = 100.0

#: The NPTS/DT line must appear within this many lines of the top of an AT2 file.
_MAX_HEADER_LINES = 12

_NPTS_RE = re.compile(r"\bNPTS\s*[=:]\s*([^\s,;]*)", re.IGNORECASE)
_DT_RE = re.compile(r"\bDT\s*[=:]\s*([^\s,;]*)", re.IGNORECASE)
# The older PEER layout: "1560    0.0200    NPTS, DT".
_OLD_RE = re.compile(r"^\s*(\S+?),?\s+(\S+?),?\s+NPTS\s*,\s*DT\b", re.IGNORECASE)
_UNITS_RE = re.compile(r"\bUNITS\s+OF\s+([^\s,;]+)", re.IGNORECASE)


def read_at2(path: str | os.PathLike) -> tuple[float, np.ndarray]:
    """Read a PEER-style AT2 accelerogram.

    The layout is free-text header lines, then a line giving the number of
    points and the sample interval, then the values (any number per line).
    Accepted NPTS/DT lines: ``NPTS= 1560, DT= .0200 SEC``,
    ``NPTS=  1560   DT=   0.0050`` and the older ``1560  0.0200  NPTS, DT``.
    A header ``UNITS OF <u>`` must say ``G``.

    Parameters
    ----------
    path : str or Path
        The AT2 file.

    Returns
    -------
    dt : float
        Sample interval (s).
    acc : ndarray, shape (n,)
        Acceleration (g) at ``t = 0, dt, ..., (n - 1) dt``.

    Raises
    ------
    ScenarioError
        If the file is missing or malformed; the message names the file, the
        line number and the bad token, or NPTS against the values found.
    """
    path = Path(path)
    try:
        text = path.read_bytes().decode("latin-1")
    except FileNotFoundError:
        raise ScenarioError(f"{path}: record file not found") from None
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read record file ({exc.strerror or exc})") from None
    lines = text.splitlines()
    head = _at2_header_line(path, lines)
    npts, dt = _at2_npts_dt(path, head + 1, lines[head])
    values: list[float] = []
    last = head + 1
    for lineno, line in enumerate(lines[head + 1 :], start=head + 2):
        tokens = line.replace(",", " ").split()
        if tokens:
            last = lineno
        for tok in tokens:
            value = _at2_number(path, lineno, tok, "an acceleration value (g)")
            if abs(value) > MAX_RECORD_G:
                raise ScenarioError(f"{path}: line {lineno}: acceleration {tok!r} g: expected at most "
                                    f"{MAX_RECORD_G:g} g in magnitude (a record in other units?)")
            values.append(value)
    if len(values) != npts:
        raise ScenarioError(
            f"{path}: line {head + 1}: NPTS = {npts} but the file holds {len(values)} values "
            f"(lines {head + 2}-{last})"
        )
    return dt, np.array(values)


def _at2_header_line(path: Path, lines: list[str]) -> int:
    """Index (0-based) of the NPTS/DT line; checks the units named above it."""
    for i, line in enumerate(lines[:_MAX_HEADER_LINES]):
        units = _UNITS_RE.search(line)
        if units and units.group(1).upper() not in ("G", "G."):
            raise ScenarioError(
                f"{path}: line {i + 1}: units {units.group(1)!r}: expected acceleration in g ('UNITS OF G')"
            )
        if "NPTS" in line.upper():
            return i
    raise ScenarioError(
        f"{path}: no 'NPTS=..., DT=...' line in the first {_MAX_HEADER_LINES} lines (not a PEER AT2 file?)"
    )


def _at2_npts_dt(path: Path, lineno: int, line: str) -> tuple[int, float]:
    npts_m, dt_m = _NPTS_RE.search(line), _DT_RE.search(line)
    if npts_m and dt_m:
        npts_tok, dt_tok = npts_m.group(1), dt_m.group(1)
    else:
        old = _OLD_RE.match(line)
        if not old:
            raise ScenarioError(
                f"{path}: line {lineno}: {line.strip()!r}: expected 'NPTS= <count>, DT= <seconds>'"
            )
        npts_tok, dt_tok = old.group(1), old.group(2)
    try:
        npts = int(npts_tok)
    except ValueError:
        npts = -1
    if npts < 1:
        raise ScenarioError(f"{path}: line {lineno}: bad NPTS token {npts_tok!r}: expected a positive integer")
    dt = _at2_number(path, lineno, dt_tok, "DT, a positive interval in s")
    if dt <= 0.0:
        raise ScenarioError(f"{path}: line {lineno}: bad DT token {dt_tok!r}: expected a positive interval in s")
    if npts < 4:
        raise ScenarioError(f"{path}: line {lineno}: NPTS = {npts}: expected at least 4 points")
    return npts, dt


def _at2_number(path: Path, lineno: int, token: str, what: str) -> float:
    try:
        value = float(token.replace("D", "E").replace("d", "e"))  # Fortran 1.0D-03
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise ScenarioError(f"{path}: line {lineno}: bad token {token!r}: expected {what}")
    return value
