"""The export-format registry and what every format shares (see :mod:`momentid.io.formats`)."""

from __future__ import annotations

import enum
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Callable, Sequence

import numpy as np

from momentid.core.resources import MEMORY_SHARE, available_memory, require_memory
from momentid.errors import ResourceError, ScenarioError, SensorDataError

__all__ = ["Layout", "ExportFormat", "SensorRecord", "FORMATS", "register", "get_format", "read_text",
           "MAX_ABS_SAMPLE", "first_absurd", "repair_missing", "require_table_memory", "MAX_REPAIR_GAP",
           "MAX_GZIP_RATIO"]

#: Largest magnitude a sample may have, in SI units (m, m/s, m/s^2).  No shake table moves a
#: kilometre or accelerates at 10^5 g; a larger cell is a corrupt or mis-scaled export, and passing
#: it on would overflow sums of squares (1e308**2 = inf) deep inside identification.
MAX_ABS_SAMPLE = 1e6

#: First two bytes of a gzip stream (RFC 1952): such files are read decompressed.
GZIP_MAGIC = b"\x1f\x8b"
#: Largest expansion of a gzip file (decompressed / compressed bytes) once it has expanded past
#: :data:`GZIP_FREE_BYTES`.  Numeric CSV compresses 2-3x (the shipped exports: 2.3x at ``gzip -9``),
#: a file of one row repeated a few hundred times; 100x leaves room for quiet records and refuses a
#: "zip bomb" (17 MB expanding to 4 GB is 240x) after the first few MB, before it fills the memory.
MAX_GZIP_RATIO = 100.0
#: Decompressed bytes below which any ratio is accepted (a small file of zeros compresses 1000x).
GZIP_FREE_BYTES = 64 * 2 ** 20
#: Decompressed bytes produced per step of the streaming decompression.
GZIP_CHUNK = 4 * 2 ** 20
#: Peak memory of reading a text file, per byte of text: the text, its lines and the parsed table.
TEXT_MEMORY_FACTOR = 4.0
#: Longest run of consecutive missing samples a reader interpolates over (the same limit as
#: identification's repair, :data:`momentid.io.run_checks.MAX_REPAIR_GAP`): 5 samples are 42 ms at
#: 120 Hz, a tenth of the shortest period of a bench-top model's modes; across a longer gap a straight
#: line would invent the response.
MAX_REPAIR_GAP = 5


class Layout(enum.Enum):
    """How an export lays out one run on disk."""

    RUN_FILE = "one file per run"
    SENSOR_FILES = "one file per sensor per run"


@dataclass(frozen=True)
class SensorRecord:
    """One sensor's file as the instrument wrote it.

    Attributes
    ----------
    path : Path
        The file read.
    time : ndarray, shape (n,)
        Device clock (s), strictly increasing; its origin is the device's own.
    step : float
        The device's nominal sample interval (s).
    acc : ndarray, shape (n, 3)
        Specific force along the sensor's axes (m/s^2), gravity included;
        ``nan`` where a sample is missing.
    axes : tuple of str, length 3
        Names of the sensor axes (``("X", "Y", "Z")``).
    info : dict
        What the file says about the device (tag, firmware, start time).
    notes : tuple of str
        What the reader repaired or converted (lost samples, units), one sentence each.
    rates : ndarray, shape (n, 3), optional
        Angular rates about the same axes (rad/s), when the export has them.
    """

    path: Path
    time: np.ndarray
    step: float
    acc: np.ndarray
    axes: tuple[str, ...] = ("X", "Y", "Z")
    info: dict = field(default_factory=dict, compare=False)
    notes: tuple[str, ...] = ()
    rates: np.ndarray | None = None


@dataclass(frozen=True)
class ExportFormat:
    """A lab export format: its ``[sensors] format`` name, layout and reader."""

    name: str
    layout: Layout
    description: str
    read_run: Callable | None = None
    read_sensor: Callable | None = None


#: Known formats by their ``[sensors] format`` name.
FORMATS: dict[str, ExportFormat] = {}


def register(fmt: ExportFormat) -> ExportFormat:
    """Add ``fmt`` to :data:`FORMATS` (its reader must fit its layout)."""
    reader = fmt.read_run if fmt.layout is Layout.RUN_FILE else fmt.read_sensor
    if reader is None or fmt.name in FORMATS:
        raise ValueError(f"format {fmt.name!r}: expected a new name and a reader for {fmt.layout.value}")
    FORMATS[fmt.name] = fmt
    return fmt


def get_format(name: str, file: Path | str, key: str = "sensors.format") -> ExportFormat:
    """The registered format ``name``; a :class:`ScenarioError` naming ``file`` and ``key`` if unknown."""
    if name not in FORMATS:
        known = ", ".join(f"{n!r} ({f.description})" for n, f in sorted(FORMATS.items()))
        raise ScenarioError(f"{file}: key '{key}' = {name!r}: expected one of {known}")
    return FORMATS[name]


def first_absurd(values: np.ndarray) -> tuple[int, int] | None:
    """``(row, column)`` index of the first sample of ``values`` (n, c) that is infinite or larger in
    magnitude than :data:`MAX_ABS_SAMPLE`, or None (``nan``, a missing sample, passes)."""
    bad = np.argwhere(np.abs(values) > MAX_ABS_SAMPLE)  # inf too; nan compares False
    return None if bad.size == 0 else (int(bad[0][0]), int(bad[0][1]))


def _gunzip(path: Path, raw: bytes) -> bytes:
    """Decompress ``raw`` chunk by chunk, refusing an expansion beyond :data:`MAX_GZIP_RATIO` or the
    memory a read may take, before it is reached (a multi-member stream is read whole, as gzip does)."""
    limit = available_memory() * MEMORY_SHARE / TEXT_MEMORY_FACTOR
    out, size, pos = [], 0, 0
    try:
        while pos < len(raw):
            unpacker = zlib.decompressobj(wbits=31)
            data = raw[pos:]
            while data and not unpacker.eof:
                piece = unpacker.decompress(data, GZIP_CHUNK)
                data = unpacker.unconsumed_tail
                out.append(piece)
                size += len(piece)
                used = len(raw) - len(data)  # compressed bytes consumed so far
                if size > GZIP_FREE_BYTES and size > MAX_GZIP_RATIO * max(used, 1):
                    raise SensorDataError(f"{path}: the gzip file expands more than {MAX_GZIP_RATIO:g} times "
                                          f"({size / 2 ** 20:.0f} MB from the first {used / 2 ** 20:.2f} MB): "
                                          f"refused as a decompression bomb; expected a compressed CSV export")
                if size > limit:
                    raise ResourceError(f"decompressing {path}", size * TEXT_MEMORY_FACTOR,
                                        limit * TEXT_MEMORY_FACTOR, "split the record into shorter files")
            if not unpacker.eof:
                raise EOFError("the compressed stream ends before its end-of-stream marker")
            rest = unpacker.unused_data
            pos = len(raw) - len(rest)
            if not rest.startswith(GZIP_MAGIC):
                break  # trailing bytes after the last member: ignored, as gzip -d does
    except (zlib.error, EOFError) as e:
        raise SensorDataError(f"{path}: broken gzip file ({e}); expected a complete gzip-compressed "
                              f"CSV file") from None
    return b"".join(out)


def read_text(path: Path) -> str:
    """The text of ``path`` (UTF-8, an optional byte-order mark, ``\\r\\n`` as ``\\n``); gzip read directly.

    Raises
    ------
    SensorDataError
        The file cannot be read, is a broken gzip stream, expands like a decompression bomb or is
        not UTF-8 text.
    ResourceError
        The file (decompressed) would not fit in the memory a read may use.
    """
    try:
        size = path.stat().st_size
    except OSError:
        size = 0
    require_memory(size * TEXT_MEMORY_FACTOR, f"reading {path}", "split the record into shorter files")
    try:
        raw = path.read_bytes()
    except IsADirectoryError:
        raise SensorDataError(f"{path}: is a directory; expected a CSV file") from None
    except OSError as e:
        raise SensorDataError(f"{path}: cannot read the file ({e.strerror}); "
                              f"expected a readable CSV file") from None
    if raw.startswith(GZIP_MAGIC):
        raw = _gunzip(path, raw)
    try:
        text = raw.decode("utf-8-sig")  # spreadsheet exports often start with a byte-order mark
    except UnicodeDecodeError as e:
        row = raw.count(b"\n", 0, e.start) + 1
        raise SensorDataError(f"{path}: row {row}, byte {e.start}: not UTF-8 text ({e.reason}); "
                              f"expected a plain-text CSV file") from None
    return text.replace("\r\n", "\n")


def require_table_memory(path: Path, rows: int, columns: int) -> None:
    """Refuse (:class:`ResourceError`) a table of ``rows`` x ``columns`` floats that would not fit,
    counting the parse's copies, before it is allocated."""
    require_memory(4.0 * 8.0 * rows * max(columns, 1), f"reading {path} ({rows} rows x {columns} columns)",
                   "split the record into shorter files")


def _runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of every run of True in a boolean vector."""
    padded = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def repair_missing(values: np.ndarray, rows: Callable[[int, int], str], names: Sequence[str], where: str,
                   what: str = "samples") -> tuple[np.ndarray, slice, list[str]]:
    """Interpolate short runs of missing (``nan``) samples; refuse long ones.

    Parameters
    ----------
    values : ndarray, shape (n, c)
        Samples on a uniform time grid, ``nan`` where missing.
    rows : callable
        ``rows(a, b)`` -> the file's rows (1-based line numbers) of grid samples ``a .. b - 1``, as
        text (``"rows 12-14"``, ``"the 2 samples lost between rows 11 and 12"``).
    names : sequence of str, length c
        Column names, for the messages.
    where : str
        The file.
    what : str
        How the messages call a sample.

    Returns
    -------
    values : ndarray, shape (n, c)
        A copy with every interior run of at most :data:`MAX_REPAIR_GAP` missing samples filled by
        linear interpolation between its neighbours on the grid.
    keep : slice
        The grid samples to keep: missing samples at the start or the end cannot be interpolated
        and are dropped.
    notes : list of str
        One per repaired or dropped run, naming its rows and the method.

    Raises
    ------
    SensorDataError
        An interior run longer than :data:`MAX_REPAIR_GAP` (naming its rows), or no sample left.
    """
    missing = np.isnan(values)
    if not missing.any():
        return values, slice(0, values.shape[0]), []
    complete = np.flatnonzero(~np.any(missing, axis=1))
    if complete.size < 2:
        raise SensorDataError(f"{where}: {int(np.all(missing, axis=1).sum())} of {values.shape[0]} {what} "
                              f"missing and no two complete ones; expected measured values")
    lo, hi = int(complete[0]), int(complete[-1]) + 1
    notes = []
    if lo or hi < values.shape[0]:
        parts = ([f"{lo} at the start ({rows(0, lo)})"] if lo else []) + (
            [f"{values.shape[0] - hi} at the end ({rows(hi, values.shape[0])})"] if hi < values.shape[0] else [])
        notes.append(f"dropped the incomplete {what} {' and '.join(parts)}: nothing to interpolate from")
    out = values[lo:hi].copy()
    grid = np.arange(out.shape[0], dtype=float)
    repaired: dict[tuple, list[str]] = {}  # the same gaps in several columns: one note
    for j, name in enumerate(names):
        gap = np.isnan(out[:, j])
        if not gap.any():
            continue
        spans = _runs_of(gap)
        for a, b in spans:
            if b - a > MAX_REPAIR_GAP:
                raise SensorDataError(
                    f"{where}: {rows(lo + a, lo + b)}, column '{name}': {b - a} consecutive "
                    f"{what} missing; expected at most {MAX_REPAIR_GAP} in a row to interpolate: a longer "
                    f"gap cannot be identified across (cut the record there)")
        ok = ~gap
        out[gap, j] = np.interp(grid[gap], grid[ok], out[ok, j])
        repaired.setdefault(tuple(spans), []).append(name)
    for spans, columns in repaired.items():
        count = sum(b - a for a, b in spans)
        spots = "; ".join(rows(lo + a, lo + b) for a, b in spans[:3])
        more = f" and {len(spans) - 3} more gaps" if len(spans) > 3 else ""
        notes.append(f"{count} missing {what if count > 1 else what.rstrip('s')} ({spots}{more}) of "
                     f"{', '.join(columns)} interpolated linearly "
                     f"between their neighbours on the uniform clock")
    return out, slice(lo, hi), notes
