"""The Xsens DOT CSV export (``[sensors] format = "xsens-dot"``): one file per sensor per run.

The file (as the Xsens DOT app writes it, gzip allowed): preamble lines
(``sep=,``, ``DeviceTag:``, ``FirmwareVersion:``, ``AppVersion:``,
``StartTime:``, a copyright line, a blank line), then a header line starting
``PacketCounter,SampleTimeFine`` and one row per sample.  Read here:

* ``SampleTimeFine``: the device clock in microseconds, an unsigned 32-bit
  counter (it wraps after about 71.6 minutes; the wrap is undone).  Each
  device has its own clock; devices synchronised by the app share it.
* ``Acc_X, Acc_Y, Acc_Z``: specific force in m/s^2 in the sensor frame,
  gravity included.

Other columns (``Euler_*``, ``Gyr_*``, ``Quat_*``, ...) are parsed for
well-formedness and ignored.  The device writes its first row before it
measures (all accelerations exactly zero): that row is dropped.  Rows the
device lost (a step of k sample intervals in ``SampleTimeFine``) become
``nan`` samples, so the time base stays uniform and the gap stays visible.
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np

from momentid.errors import SensorDataError
from momentid.io.formats.base import MAX_ABS_SAMPLE, ExportFormat, Layout, SensorRecord, first_absurd, read_text, register

__all__ = ["read_xsens_dot", "CLOCK_COLUMN", "ACC_COLUMNS"]

CLOCK_COLUMN = "SampleTimeFine"
ACC_COLUMNS = ("Acc_X", "Acc_Y", "Acc_Z")
#: Microseconds per second (``SampleTimeFine`` counts microseconds).
CLOCK_TICKS_PER_SECOND = 1e6
#: ``SampleTimeFine`` is a uint32 counter of microseconds.
CLOCK_WRAP = 2 ** 32
#: Lines searched for the header before giving up (the app writes 7 preamble lines).
MAX_PREAMBLE_LINES = 20
#: Largest departure of a clock step from a whole number of sample intervals,
#: as a fraction of the interval: the DOT clock ticks in whole microseconds
#: (8333 us at 120 Hz), so a real step is exact; 5 % still names jitter.
STEP_TOLERANCE = 0.05
#: Fewest samples a sensor file must hold.
MIN_SAMPLES = 3
#: Largest ratio of the clock's span (in samples) to the rows present: a file whose clock says it
#: lost more samples than it holds is refused (the lost ones would be nan, and a jump of the clock to
#: a wild value would otherwise allocate billions of them).
MAX_SPAN_PER_ROW = 2
#: Cells read as a missing sample.
MISSING_CELLS = ("", "nan", "NaN", "NAN")


def _error(path: Path, row: int, column: str, message: str) -> SensorDataError:
    return SensorDataError(f"{path}: row {row}, column {column}: {message}")


def _preamble(path: Path, lines: list[str]) -> tuple[int, dict]:
    """Index of the header line and the preamble's ``key:,value`` pairs."""
    info = {}
    for i, line in enumerate(lines[:MAX_PREAMBLE_LINES]):
        if line.startswith("PacketCounter") or line.startswith(CLOCK_COLUMN):
            return i, info
        key, sep, value = line.partition(",")
        if sep and key.strip().endswith(":"):
            info[key.strip().rstrip(":").strip()] = value.strip()
    raise SensorDataError(f"{path}: no header line starting 'PacketCounter,{CLOCK_COLUMN}' in the first "
                          f"{MAX_PREAMBLE_LINES} lines; expected an Xsens DOT CSV export "
                          f"(preamble, then the header, then one row per sample)")


def _parse_slowly(path: Path, rows: list[str], names: tuple[str, ...], first_row: int) -> np.ndarray:
    out = np.empty((len(rows), len(names)))
    for i, line in enumerate(rows):
        fields = line.split(",")
        if len(fields) != len(names):
            raise _error(path, first_row + i, f"'{names[min(len(fields), len(names) - 1)]}'",
                         f"the row has {len(fields)} fields, expected {len(names)} ({','.join(names)})")
        for j, cell in enumerate(fields):
            text = cell.strip()
            if text in MISSING_CELLS:
                out[i, j] = np.nan
                continue
            try:
                out[i, j] = float(text)
            except ValueError:
                raise _error(path, first_row + i, f"'{names[j]}'",
                             f"{text!r} is not a number; expected a decimal number or an empty cell "
                             f"for a missing sample") from None
    return out


def _parse(path: Path, body: str, names: tuple[str, ...], first_row: int) -> np.ndarray:
    n = body.count("\n") + 1
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = np.loadtxt(io.StringIO(body), delimiter=",", comments=None, quotechar=None,
                              dtype=float, ndmin=2)
    except ValueError:
        data = None
    if data is None or data.shape != (n, len(names)):
        data = _parse_slowly(path, body.split("\n"), names, first_row)
    return data


def _grid(path: Path, ticks: np.ndarray, first_row: int) -> tuple[np.ndarray, float, float]:
    """Sample index of each row on the device's uniform clock, the first tick and the interval (ticks)."""
    bad = np.flatnonzero(~((ticks >= 0) & (ticks < CLOCK_WRAP)))  # nan too
    if bad.size:
        i = int(bad[0])
        raise _error(path, first_row + i, f"'{CLOCK_COLUMN}'",
                     f"{float(ticks[i])!r}; expected the device clock (us, a uint32 counter from 0 to "
                     f"{CLOCK_WRAP - 1}) on every row")
    step_all = np.diff(ticks)
    step_all[step_all < -CLOCK_WRAP / 2] += CLOCK_WRAP  # the uint32 counter wrapped
    ticks = ticks[0] + np.concatenate([[0.0], np.cumsum(step_all)])
    step = float(np.median(step_all))
    if not step > 0:
        raise _error(path, first_row, f"'{CLOCK_COLUMN}'", "does not advance; expected a running clock (us)")
    k = step_all / step
    off = np.flatnonzero((k < 1 - STEP_TOLERANCE) | (np.abs(k - np.round(k)) > STEP_TOLERANCE))
    if off.size:
        i = int(off[0]) + 1
        raise _error(path, first_row + i, f"'{CLOCK_COLUMN}'",
                     f"{ticks[i]:.0f} us is {step_all[i - 1]:.0f} us after the row before; expected a "
                     f"whole number of sample intervals ({step:.0f} us): the clock went back or jittered")
    index = np.round((ticks - ticks[0]) / step).astype(np.int64)
    if index[-1] + 1 > MAX_SPAN_PER_ROW * index.size:
        i = int(np.argmax(step_all)) + 1
        raise _error(path, first_row + i, f"'{CLOCK_COLUMN}'",
                     f"{ticks[i]:.0f} us is {step_all[i - 1]:.0f} us ({step_all[i - 1] / step:.0f} sample "
                     f"intervals) after the row before; expected at most {MAX_SPAN_PER_ROW - 1} lost samples "
                     f"per recorded one: the file lost more than it holds")
    return index, ticks[0], step


def read_xsens_dot(path) -> SensorRecord:
    """Read one Xsens DOT CSV export (plain or gzip-compressed).

    Parameters
    ----------
    path : str or Path
        The file.

    Returns
    -------
    SensorRecord
        ``time`` (n,) s on the device clock (uniform; rows the device lost are
        ``nan`` samples in ``acc``), ``acc`` (n, 3) m/s^2 along the sensor's
        X, Y, Z with gravity, ``info`` the preamble (``DeviceTag``,
        ``FirmwareVersion``, ``StartTime``, ...) plus ``lost_samples``.

    Raises
    ------
    SensorDataError
        Naming the file, row (1-based line number) and column.
    """
    path = Path(path)
    lines = read_text(path).rstrip().split("\n")
    h, info = _preamble(path, lines)
    names = tuple(c.strip() for c in lines[h].split(","))
    for column in (CLOCK_COLUMN, *ACC_COLUMNS):
        if column not in names:
            raise _error(path, h + 1, f"'{column}'", f"missing from the header {lines[h]!r}; expected "
                                                     f"{CLOCK_COLUMN} and {', '.join(ACC_COLUMNS)}")
    first_row = h + 2
    body = "\n".join(lines[h + 1:])
    if len(lines) - h - 1 < MIN_SAMPLES or not body.strip():
        raise _error(path, first_row, f"'{CLOCK_COLUMN}'",
                     f"{len(lines) - h - 1} data rows; expected at least {MIN_SAMPLES} samples")
    data = _parse(path, body, names, first_row)
    acc = data[:, [names.index(c) for c in ACC_COLUMNS]]
    absurd = first_absurd(acc)
    if absurd is not None:
        i, j = absurd
        raise _error(path, first_row + i, f"'{ACC_COLUMNS[j]}'",
                     f"{float(acc[i, j])!r} m/s^2; expected a finite acceleration of magnitude at most "
                     f"{MAX_ABS_SAMPLE:g} m/s^2 (or an empty cell for a lost sample)")
    ticks = data[:, names.index(CLOCK_COLUMN)]
    if np.all(acc[0] == 0.0):  # written before the device measures
        acc, ticks, first_row = acc[1:], ticks[1:], first_row + 1
    index, start, step = _grid(path, ticks, first_row)
    full = np.full((int(index[-1]) + 1, 3), np.nan)
    full[index] = acc
    info = dict(info, lost_samples=int(full.shape[0] - index.size))
    time = (start + np.arange(full.shape[0]) * step) / CLOCK_TICKS_PER_SECOND
    return SensorRecord(path=path, time=time, step=step / CLOCK_TICKS_PER_SECOND, acc=full,
                        axes=("X", "Y", "Z"), info=info)


register(ExportFormat(name="xsens-dot", layout=Layout.SENSOR_FILES, read_sensor=read_xsens_dot,
                      description="Xsens DOT CSV export, one file per sensor"))
