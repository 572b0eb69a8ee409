"""The export-format registry and what every format shares (see :mod:`momentid.io.formats`)."""

from __future__ import annotations

import enum
import gzip
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from momentid.errors import ScenarioError, SensorDataError

__all__ = ["Layout", "ExportFormat", "SensorRecord", "FORMATS", "register", "get_format", "read_text",
           "MAX_ABS_SAMPLE", "first_absurd"]

#: Largest magnitude a sample may have, in SI units (m, m/s, m/s^2).  No shake table moves a
#: kilometre or accelerates at 10^5 g; a larger cell is a corrupt or mis-scaled export, and passing
#: it on would overflow sums of squares (1e308**2 = inf) deep inside identification.
MAX_ABS_SAMPLE = 1e6

#: First two bytes of a gzip stream (RFC 1952): such files are read decompressed.
GZIP_MAGIC = b"\x1f\x8b"


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
    """

    path: Path
    time: np.ndarray
    step: float
    acc: np.ndarray
    axes: tuple[str, ...] = ("X", "Y", "Z")
    info: dict = field(default_factory=dict, compare=False)


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


def read_text(path: Path) -> str:
    """The text of ``path`` (UTF-8, an optional byte-order mark, ``\\r\\n`` as ``\\n``); gzip read directly.

    Raises
    ------
    SensorDataError
        The file cannot be read, is a broken gzip stream or is not UTF-8 text.
    """
    try:
        raw = path.read_bytes()
    except IsADirectoryError:
        raise SensorDataError(f"{path}: is a directory; expected a CSV file") from None
    except OSError as e:
        raise SensorDataError(f"{path}: cannot read the file ({e.strerror}); "
                              f"expected a readable CSV file") from None
    if raw.startswith(GZIP_MAGIC):
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as e:
            raise SensorDataError(f"{path}: broken gzip file ({e}); expected a complete gzip-compressed "
                                  f"CSV file") from None
    try:
        text = raw.decode("utf-8-sig")  # spreadsheet exports often start with a byte-order mark
    except UnicodeDecodeError as e:
        row = raw.count(b"\n", 0, e.start) + 1
        raise SensorDataError(f"{path}: row {row}, byte {e.start}: not UTF-8 text ({e.reason}); "
                              f"expected a plain-text CSV file") from None
    return text.replace("\r\n", "\n")
