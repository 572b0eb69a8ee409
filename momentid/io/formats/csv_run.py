"""The one-CSV-per-run format (``[sensors] format = "csv"``, the default).

A header naming the columns ``t``, ``zdd``, ``a1..ad`` (required),
``q1..qd``, ``v1..vd`` (optional, each group all or none) and ``z``, ``zd``
(optional), an IMU table's other motions ``table_ay``, ``table_az`` (m/s^2),
``table_wx``, ``table_wy``, ``table_wz`` (rad/s) (optional), in any order, then
one row per sample in SI units.  A mistake
inside a file is a :class:`~momentid.errors.SensorDataError` naming the file,
the row (the 1-based line number, the header is row 1) and the column.

Parsing takes the fast path (``np.loadtxt``); only when it fails is the file
scanned line by line to name the first bad row and column.
"""

from __future__ import annotations

import io
import os
import warnings
from pathlib import Path

import numpy as np

from momentid.core.series import TABLE_MOTION, channel_unit
from momentid.errors import SensorDataError
from momentid.io.formats.base import (MAX_ABS_SAMPLE, ExportFormat, Layout, first_absurd, read_text, register,
                                      require_table_memory)

__all__ = ["read_csv_run", "csv_error", "TIME_TOLERANCE", "MIN_SAMPLES"]

#: Largest departure of a time stamp's step (and of the stamp itself) from
#: the uniform clock, as a fraction of the sample interval.  1 % accepts
#: time stamps printed with 6 decimals at 1 kHz (a rounding error of at most
#: 0.1 % of the interval per step) and refuses a dropped sample (100 %) or
#: real clock jitter.
TIME_TOLERANCE = 0.01
#: Fewest samples a run may have (identification's ``check_run`` needs 3).
MIN_SAMPLES = 3


def _header_help(d: int) -> str:
    return (f"t, zdd, a1..a{d} and optionally q1..q{d}, v1..v{d} (each group all or none), z, zd, "
            f"{', '.join(TABLE_MOTION)} (d = {d} storeys from experiment.toml)")


def _unit(name: str) -> str:
    return "s" if name == "t" else channel_unit(name)


def csv_error(path: Path, row: int, column: str, message: str) -> SensorDataError:
    """A one-line error about ``column`` (a quoted name or a description) of line ``row``."""
    return SensorDataError(f"{path}: row {row}, column {column}: {message}")


def _columns(path: Path, header: str, d: int) -> tuple[str, ...]:
    """Validate the header line (row 1) against the vocabulary for ``d`` storeys."""
    names = tuple(c.strip() for c in header.split(","))
    if d > len(names):  # before anything of size d is built
        floors = sum(1 for n in names if n[:1] == "a" and n[1:].isdigit())
        raise csv_error(path, 1, f"'a{floors + 1}'", f"missing: the header has {floors} floor accelerations of the "
                                                     f"{d} storeys experiment.toml states; expected the columns "
                                                     f"{_header_help(d)}")
    groups = {g: tuple(f"{g}{i + 1}" for i in range(d)) for g in ("a", "q", "v")}
    known = {"t", "zdd", "z", "zd", *groups["a"], *groups["q"], *groups["v"], *TABLE_MOTION}
    seen: set[str] = set()
    for j, name in enumerate(names):
        if name not in known:
            what = f"'{name}'" if name else f"{j + 1} (no name)"
            raise csv_error(path, 1, what, f"unknown column; expected only the columns {_header_help(d)}")
        if name in seen:
            raise csv_error(path, 1, f"'{name}'", "appears twice in the header; expected each column once")
        seen.add(name)
    for name in ("t", "zdd", *groups["a"]):
        if name not in seen:
            raise csv_error(path, 1, f"'{name}'", f"missing from the header {header.strip()!r}; expected "
                                                   f"the columns {_header_help(d)}")
    for g in ("q", "v"):
        present = [c for c in groups[g] if c in seen]
        if present and len(present) < d:
            missing = next(c for c in groups[g] if c not in seen)
            raise csv_error(path, 1, f"'{missing}'", f"missing while {', '.join(present)} are present; "
                                                      f"expected all of {g}1..{g}{d} or none")
    return names


def _parse_slowly(path: Path, rows: list[str], names: tuple[str, ...]) -> np.ndarray:
    """Parse ``rows`` (lines 2.. of the file) cell by cell; raise at the first bad one."""
    out = np.empty((len(rows), len(names)))
    for i, line in enumerate(rows):
        row = i + 2
        if not line.strip():
            raise csv_error(path, row, f"'{names[0]}'", "empty line; expected one sample per line, "
                                                         "without blank lines between samples")
        fields = line.split(",")
        if len(fields) < len(names):
            raise csv_error(path, row, f"'{names[len(fields)]}'",
                             f"missing: the row has {len(fields)} fields, expected {len(names)} "
                             f"({','.join(names)})")
        if len(fields) > len(names):
            raise csv_error(path, row, f"{len(names) + 1} (after '{names[-1]}')",
                             f"extra field {fields[len(names)].strip()!r}: the row has {len(fields)} fields, "
                             f"expected {len(names)} ({','.join(names)})")
        for j, (cell, name) in enumerate(zip(fields, names)):
            text = cell.strip()
            if not text:
                raise csv_error(path, row, f"'{name}'", f"empty cell; expected a number ({_unit(name)})")
            try:
                out[i, j] = float(text)
            except ValueError:
                raise csv_error(path, row, f"'{name}'", f"{text!r} is not a number; expected a decimal "
                                                         f"number ({_unit(name)})") from None
    return out


def _parse(path: Path, body: str, names: tuple[str, ...]) -> np.ndarray:
    """``(n, c)`` floats of the data rows (``body``: lines 2.. of the file, no trailing newline):
    numpy's C reader, or the slow scan that names the first bad row and column."""
    n = body.count("\n") + 1
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data": the shape check below catches it
            data = np.loadtxt(io.StringIO(body), delimiter=",", comments=None, quotechar=None,
                              dtype=float, ndmin=2)
    except ValueError:
        data = None
    if data is None or data.shape != (n, len(names)):  # loadtxt skips blank lines
        data = _parse_slowly(path, body.split("\n"), names)
    return data


def _uniform_time(path: Path, t: np.ndarray) -> np.ndarray:
    """Check the time column (rows are ``index + 2``) and return it as an exact uniform grid."""
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        i = int(bad[0])
        raise csv_error(path, i + 2, "'t'", f"{float(t[i])!r}; expected a finite time (s)")
    step = np.diff(t)
    back = np.flatnonzero(step <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise csv_error(path, i + 2, "'t'", f"{float(t[i])!r} s does not increase on row {i + 1} "
                                             f"({float(t[i - 1])!r} s); expected strictly increasing times")
    h = float(np.median(step))
    off = np.flatnonzero(np.abs(step - h) > TIME_TOLERANCE * h)
    if off.size:
        i = int(off[0]) + 1
        raise csv_error(path, i + 2, "'t'",
                         f"{float(t[i])!r} s is {step[i - 1]:.6g} s after row {i + 1}; expected uniform "
                         f"sampling every {h:.6g} s (within {TIME_TOLERANCE:.0%}): a gap or clock jitter "
                         f"cannot be identified across")
    n = t.size
    grid = t[0] + np.arange(n) * ((t[-1] - t[0]) / (n - 1))
    drift = np.flatnonzero(np.abs(t - grid) > TIME_TOLERANCE * h)
    if drift.size:
        i = int(drift[0])
        raise csv_error(path, i + 2, "'t'",
                         f"{float(t[i])!r} s is {t[i] - grid[i]:.3g} s off the uniform clock from "
                         f"{float(t[0])!r} s to {float(t[-1])!r} s; expected a steady sample rate")
    return grid


def read_csv_run(path: str | os.PathLike, storeys: int) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """Read and check one run's CSV file.

    Parameters
    ----------
    path : str or Path
        The CSV file (header row, then one row per sample, SI units).
    storeys : int
        ``d``: the file must hold ``a1..ad`` (and ``q``, ``v`` all or none).

    Returns
    -------
    time : ndarray, shape (n,)
        Sample times (s) on the exact uniform grid from the first to the last
        stamp (the stamps are checked to lie within :data:`TIME_TOLERANCE` of
        a sample interval from it; this removes the rounding of printed times).
    channels : tuple of str, length c
        The header's columns in file order, without ``t``.
    values : ndarray, shape (n, c)
        The samples; ``nan`` cells (explicit missing samples) are kept for
        identification to repair or refuse.  An infinite cell or one larger
        than :data:`~momentid.io.formats.MAX_ABS_SAMPLE` is refused.

    Raises
    ------
    SensorDataError
        Naming the file, the row (1-based line number) and the column.
    """
    path = Path(path)
    text = read_text(path).rstrip()  # trailing newlines (and spaces) end no row
    if not text:
        raise csv_error(path, 1, "'t'", f"the file is empty; expected a header row with the columns "
                                         f"{_header_help(storeys)}, then one row per sample")
    header, _, body = text.partition("\n")
    names = _columns(path, header, storeys)
    rows = body.count("\n") + 1 if body else 0
    if rows < MIN_SAMPLES:
        raise csv_error(path, rows + 2, "'t'", f"{rows} data rows; expected at least {MIN_SAMPLES} samples")
    require_table_memory(path, rows, len(names))
    data = _parse(path, body, names)
    k = names.index("t")
    time = _uniform_time(path, data[:, k])
    channels = names[:k] + names[k + 1:]
    values = np.ascontiguousarray(np.delete(data, k, axis=1))
    absurd = first_absurd(values)
    if absurd is not None:
        i, j = absurd
        raise csv_error(path, i + 2, f"'{channels[j]}'",
                        f"{float(values[i, j])!r} {channel_unit(channels[j])}; expected a finite number "
                        f"of magnitude at most {MAX_ABS_SAMPLE:g} in SI units (or nan for a missing sample)")
    return time, channels, values


register(ExportFormat(name="csv", layout=Layout.RUN_FILE, read_run=read_csv_run,
                      description="one CSV per run: t, zdd, a1..ad in SI units"))
