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

* ``Gyr_X, Gyr_Y, Gyr_Z`` (when present): angular rate in deg/s in the sensor
  frame, read as ``rates`` in rad/s.  They are secondary: a gap or a wild
  value in them drops the rates with a note and keeps the accelerations.

* ``PacketCounter``: a 16-bit packet counter (it wraps at 65536; the wrap
  is undone); it places a row whose ``SampleTimeFine`` cell is empty.

Other columns (``Euler_*``, ``Quat_*``, ...) are parsed for
well-formedness and ignored.  The device writes its first row before it
measures (all accelerations exactly zero): that row is dropped.

Lost packets show two ways: the clock steps k sample intervals (k - 1
samples never arrived), or the app writes a row for the lost packet with
``nan``/``inf`` in every channel, stamped with the stamp of the row before
(whose own stamp then jumps two intervals) while ``PacketCounter`` runs on.
Such rows are dropped and every sample is placed by its stamp; a missing
sample (lost, or an empty cell) is then interpolated linearly when at most
:data:`~momentid.io.formats.base.MAX_REPAIR_GAP` are missing in a row, with a
note naming the rows; a longer gap is an error naming them.  An export in g
(gravity reads ~1) is converted to m/s^2 with a note.  Variants that change no
sample are undone with a note: a trailing comma (header or data rows), empty
lines, a last row cut short and a row that repeats an earlier row exactly.
"""

from __future__ import annotations

import io
import os
import warnings
from pathlib import Path

import numpy as np

from momentid.errors import SensorDataError
from momentid.io.formats.base import (MAX_ABS_SAMPLE, ExportFormat, Layout, SensorRecord, first_absurd, read_text,
                                      register, repair_missing, require_table_memory)

__all__ = ["read_xsens_dot", "CLOCK_COLUMN", "ACC_COLUMNS", "RATE_COLUMNS"]

CLOCK_COLUMN = "SampleTimeFine"
COUNTER_COLUMN = "PacketCounter"
#: ``PacketCounter`` is a uint16 counter of packets.
COUNTER_WRAP = 2 ** 16
ACC_COLUMNS = ("Acc_X", "Acc_Y", "Acc_Z")
#: Angular rates (deg/s, the DOT's unit), read when all three are present.
RATE_COLUMNS = ("Gyr_X", "Gyr_Y", "Gyr_Z")
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
#: Largest angular rate (deg/s) read as one: the DOT's gyroscope spans +-2000 deg/s.
MAX_RATE = 2000.0
#: Radians per degree.
DEGREE = np.pi / 180
#: Standard gravity (m/s^2): an export in g is converted with it.
STANDARD_GRAVITY = 9.80665
#: Magnitude (m/s^2) of the mean acceleration of a sensor under gravity: 9.78-10.15 on the shipped
#: DOTs (latitude, calibration and a tilt-dependent offset of a few percent); a wider band still
#: tells m/s^2 from g (a factor 9.8) and refuses anything else (a unit neither, a broken sensor).
GRAVITY_RANGE = (8.0, 11.6)


def _error(path: Path, row: int, column: str, message: str) -> SensorDataError:
    return SensorDataError(f"{path}: row {row}, column {column}: {message}")


def _preamble(path: Path, lines: list[str]) -> tuple[int, dict]:
    """Index of the header line and the preamble's ``key:,value`` pairs."""
    info = {}
    for i, line in enumerate(lines[:MAX_PREAMBLE_LINES]):
        if line.startswith("PacketCounter") or line.startswith(CLOCK_COLUMN):
            return i, info
        key, sep, value = line.replace(";", ",", 1).partition(",")  # ';' in a decimal-comma locale
        if sep and key.strip().endswith(":"):
            info[key.strip().rstrip(":").strip()] = value.strip()
    raise SensorDataError(f"{path}: no header line starting 'PacketCounter,{CLOCK_COLUMN}' in the first "
                          f"{MAX_PREAMBLE_LINES} lines; expected an Xsens DOT CSV export "
                          f"(preamble, then the header, then one row per sample)")


def _decimal_commas(lines: list[str], h: int) -> tuple[list[str], list[str]]:
    """``lines`` with the header at ``h`` read as written: an export of a locale that writes decimal
    commas separates its cells by ';' (header ``PacketCounter;SampleTimeFine;...``); its cells are
    rewritten with '.' and ',' and a note says so."""
    if "," in lines[h] or ";" not in lines[h]:
        return lines, []
    rows = [line.replace(",", ".").replace(";", ",") for line in lines[h:]]
    return lines[:h] + rows, ["cells separated by ';' with decimal commas (a locale's export): read as such"]


def _parse_slowly(path: Path, rows: list[str], names: tuple[str, ...], numbers: np.ndarray) -> np.ndarray:
    out = np.empty((len(rows), len(names)))
    for i, line in enumerate(rows):
        fields = line.split(",")
        if len(fields) != len(names):
            raise _error(path, int(numbers[i]), f"'{names[min(len(fields), len(names) - 1)]}'",
                         f"the row has {len(fields)} fields, expected {len(names)} ({','.join(names)})")
        for j, cell in enumerate(fields):
            text = cell.strip()
            if text in MISSING_CELLS:
                out[i, j] = np.nan
                continue
            try:
                out[i, j] = float(text)
            except ValueError:
                raise _error(path, int(numbers[i]), f"'{names[j]}'",
                             f"{text!r} is not a number; expected a decimal number or an empty cell "
                             f"for a missing sample") from None
    return out


def _parse(path: Path, rows: list[str], names: tuple[str, ...], numbers: np.ndarray) -> np.ndarray:
    """The cells of ``rows`` (their line numbers: ``numbers``) as floats, one column per name."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = np.loadtxt(io.StringIO("\n".join(rows)), delimiter=",", comments=None, quotechar=None,
                              dtype=float, ndmin=2)
    except ValueError:
        data = None
    if data is None or data.shape != (len(rows), len(names)):
        data = _parse_slowly(path, rows, names, numbers)
    return data


def _harmless_variants(names: tuple[str, ...], rows: list[str], first_row: int):
    """Export variants that change no sample, undone with a note: a trailing comma (an empty cell
    beyond the header's columns, on the header or on data rows), empty lines, a last row cut short (an
    export that ends mid-row: the sample is lost, as at any end) and a row that repeats an earlier row
    exactly (every cell; genuine rows never do: each has its own stamp and packet count).

    Returns
    -------
    names : tuple of str
    rows : list of str
        The data rows kept, trailing commas removed.
    numbers : ndarray of int
        Their line numbers (1-based) in the file.
    notes : list of str
    """
    notes = []
    if len(names) > 1 and names[-1] == "":
        names = names[:-1]
    width = len(names) - 1                    # commas in a row of the header's width
    trailing = [i for i, row in enumerate(rows) if row.count(",") == width + 1 and not row.rsplit(",", 1)[1].strip()]
    if trailing:
        for i in trailing:
            rows[i] = rows[i].rsplit(",", 1)[0]
        which = (f"every data row (rows {first_row}-{first_row + len(rows) - 1}) ends" if len(trailing) == len(rows)
                 else f"{_row_list(first_row + np.array(trailing))} end")
        notes.append(f"{which} in a comma (an empty cell beyond the header's {len(names)} columns): ignored")
    blank = [i for i, row in enumerate(rows) if not row.strip()]
    filled = [i for i, row in enumerate(rows) if row.strip()]
    cut = filled[-1:] if filled and rows[filled[-1]].count(",") < width else []
    seen, repeated = set(), []
    for i in filled:
        if rows[i] in seen:
            repeated.append(i)
        seen.add(rows[i])
    numbers = first_row + np.arange(len(rows))
    for dropped, why in ((blank, "empty: skipped"),
                         (cut, f"cut short ({rows[cut[0]].count(',') + 1 if cut else 0} of {len(names)} cells: the "
                               f"export ends mid-row): dropped"),
                         (repeated, "repeat(s) an earlier row exactly (every cell; a duplicated export line): "
                                    "dropped")):
        if dropped:
            notes.append(f"{_row_list(numbers[dropped])}: {why}")
    if blank or cut or repeated:
        keep = np.setdiff1d(np.arange(len(rows)), blank + cut + repeated)
        rows, numbers = [rows[i] for i in keep], numbers[keep]
    return names, rows, numbers, notes


def _placeholders(path: Path, acc: np.ndarray, ticks: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Rows the app wrote for packets it lost: every acceleration non-finite (``nan``/``inf``).  Returns
    the mask of those rows and a note naming them and the stamp each repeats (the app stamps such a
    row with the time of the row before it, whose own stamp then jumps two intervals)."""
    lost = ~np.any(np.isfinite(acc), axis=1)
    if not lost.any():
        return lost, []
    repeats = [int(rows[i]) for i in np.flatnonzero(lost) if i > 0 and ticks[i] == ticks[i - 1]]
    where = _row_list(rows[lost])
    note = (f"{where}: no acceleration (every cell empty, nan or inf: {int(lost.sum())} lost "
            f"packet{'s' if lost.sum() > 1 else ''}), row{'s' if lost.sum() > 1 else ''} dropped; the samples "
            f"are placed by {CLOCK_COLUMN}")
    if repeats:
        note += f" ({_row_list(np.array(repeats))} repeat{'s' if len(repeats) == 1 else ''} the stamp of the row " \
                f"before: the stamp of the lost packet)"
    return lost, [note]


def _stamps_from_counter(ticks: np.ndarray, counter: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Rows without a ``SampleTimeFine`` stamp placed by ``PacketCounter`` (uint16, its wrap undone)
    from the nearest stamped row before them; left as they are (for :func:`_grid` to name) when the
    counter cannot place them."""
    missing = ~np.isfinite(ticks)
    ok = np.isfinite(ticks)
    if not missing.any() or not np.all(np.isfinite(counter)) or ok.sum() < 2 or not ok[0]:
        return ticks, []
    if np.any((counter < 0) | (counter >= COUNTER_WRAP) | (counter != np.round(counter))):
        return ticks, []
    packets = np.concatenate([[0.0], np.cumsum(np.diff(counter) % COUNTER_WRAP)])
    moved = np.diff(packets[ok])
    if not np.all(moved > 0):
        return ticks, []
    step = float(np.median(np.diff(ticks[ok]) / moved))
    previous = np.maximum.accumulate(np.where(ok, np.arange(ticks.size), 0))
    out = ticks.copy()
    out[missing] = (ticks[previous[missing]] + (packets[missing] - packets[previous[missing]]) * step) % CLOCK_WRAP
    return out, [f"{_row_list(rows[missing])}: no {CLOCK_COLUMN} stamp; placed by {COUNTER_COLUMN} "
                 f"({step:.0f} us per packet)"]


def _check_clock_step(path: Path, ticks: np.ndarray, counter: np.ndarray, rows: np.ndarray) -> None:
    """Refuse stamps that move on by more sample intervals than ``PacketCounter`` counts packets, and
    never make it up: the device clock stepped (a re-synchronisation), no sample was lost.  (The app's
    lost-packet mark jumps a stamp and repeats it on the next row: that evens out at once.)"""
    if ticks.size < 3 or not (np.all(np.isfinite(counter)) and np.all(np.isfinite(ticks))):
        return
    packets = np.concatenate([[0.0], np.cumsum(np.diff(counter) % COUNTER_WRAP)])
    moved = np.diff(ticks)
    moved[moved < -CLOCK_WRAP / 2] += CLOCK_WRAP  # the uint32 counter wrapped
    forward = moved[moved > 0]
    if forward.size < 2:
        return
    step = float(np.median(forward))
    slots = np.concatenate([[0.0], np.cumsum(np.round(moved / step))])
    ahead = slots - packets  # sample intervals the stamps are ahead of the packets counted
    if ahead[-1] <= 0:
        return
    i = int(np.flatnonzero(ahead != ahead[-1])[-1]) + 1 if np.any(ahead != ahead[-1]) else 0
    if i == 0:
        return
    raise _error(path, int(rows[i]), f"'{CLOCK_COLUMN}'",
                 f"{ticks[i]:.0f} us is {moved[i - 1]:.0f} us after row {int(rows[i - 1])} while {COUNTER_COLUMN} "
                 f"moves on by {packets[i] - packets[i - 1]:.0f}: the device clock stepped "
                 f"{ahead[-1] * step / 1e3:+.1f} ms "
                 f"and no packet was lost; expected stamps that follow the packet counter (re-export, or cut "
                 f"the record there)")


def _row_list(rows: np.ndarray) -> str:
    """``"row 12"``, ``"rows 12, 40"`` or ``"rows 12, 40, 77 and 5 more"``."""
    shown = ", ".join(str(int(r)) for r in rows[:3])
    more = f" and {rows.size - 3} more" if rows.size > 3 else ""
    return f"row{'s' if rows.size > 1 else ''} {shown}{more}"


def _grid(path: Path, ticks: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Sample index of each row on the device's uniform clock, the first tick and the interval (ticks);
    ``rows`` are the rows' line numbers, for the messages."""
    bad = np.flatnonzero(~((ticks >= 0) & (ticks < CLOCK_WRAP)))  # nan too
    if bad.size:
        i = int(bad[0])
        raise _error(path, int(rows[i]), f"'{CLOCK_COLUMN}'",
                     f"{float(ticks[i])!r}; expected the device clock (us, a uint32 counter from 0 to "
                     f"{CLOCK_WRAP - 1}) on every row")
    step_all = np.diff(ticks)
    step_all[step_all < -CLOCK_WRAP / 2] += CLOCK_WRAP  # the uint32 counter wrapped
    ticks = ticks[0] + np.concatenate([[0.0], np.cumsum(step_all)])
    step = float(np.median(step_all))
    if not step > 0:
        raise _error(path, int(rows[0]), f"'{CLOCK_COLUMN}'", "does not advance; expected a running clock (us)")
    same = np.flatnonzero(step_all == 0)
    if same.size:
        i = int(same[0]) + 1
        raise _error(path, int(rows[i]), f"'{CLOCK_COLUMN}'",
                     f"{ticks[i]:.0f} us repeats the stamp of row {int(rows[i - 1])}; expected one row per "
                     f"sample (a repeated stamp is the app's mark of a lost packet only on a row whose "
                     f"accelerations are all nan/inf)")
    k = step_all / step
    off = np.flatnonzero((k < 1 - STEP_TOLERANCE) | (np.abs(k - np.round(k)) > STEP_TOLERANCE))
    if off.size:
        i = int(off[0]) + 1
        what = "went back" if step_all[i - 1] < 0 else "jittered"
        raise _error(path, int(rows[i]), f"'{CLOCK_COLUMN}'",
                     f"{ticks[i]:.0f} us is {step_all[i - 1]:.0f} us after row {int(rows[i - 1])}; expected a "
                     f"whole number of sample intervals ({step:.0f} us): the clock {what}")
    index = np.round((ticks - ticks[0]) / step).astype(np.int64)
    if index[-1] + 1 > MAX_SPAN_PER_ROW * index.size:
        i = int(np.argmax(step_all)) + 1
        raise _error(path, int(rows[i]), f"'{CLOCK_COLUMN}'",
                     f"{ticks[i]:.0f} us is {step_all[i - 1]:.0f} us ({step_all[i - 1] / step:.0f} sample "
                     f"intervals) after the row before; expected at most {MAX_SPAN_PER_ROW - 1} lost samples "
                     f"per recorded one: the file lost more than it holds")
    return index, ticks[0], step


def _units(path: Path, acc: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Accelerations in m/s^2: an export in g (gravity reads ~1) is converted with a note; a gravity
    that is neither is refused (a sensor at rest on Earth reads 1 g whatever its mounting)."""
    gravity = float(np.linalg.norm(np.nanmean(acc, axis=0)))
    if GRAVITY_RANGE[0] <= gravity <= GRAVITY_RANGE[1]:
        return acc, []
    if GRAVITY_RANGE[0] <= gravity * STANDARD_GRAVITY <= GRAVITY_RANGE[1]:
        return acc * STANDARD_GRAVITY, [
            f"accelerations in g (gravity reads {gravity:.3f}): converted to m/s^2 (x {STANDARD_GRAVITY})"]
    raise SensorDataError(f"{path}: gravity reads {gravity:.4g} (the magnitude of the mean of "
                          f"{', '.join(ACC_COLUMNS)}); expected {GRAVITY_RANGE[0]:g}-{GRAVITY_RANGE[1]:g} m/s^2 "
                          f"(or the same in g): not accelerations of a sensor under gravity, or an unknown unit")


def read_xsens_dot(path: str | os.PathLike) -> SensorRecord:
    """Read one Xsens DOT CSV export (plain or gzip-compressed).

    Parameters
    ----------
    path : str or Path
        The file.

    Returns
    -------
    SensorRecord
        ``time`` (n,) s on the device clock (uniform), ``acc`` (n, 3) m/s^2
        along the sensor's X, Y, Z with gravity: lost packets and empty cells
        (at most :data:`~momentid.io.formats.base.MAX_REPAIR_GAP` in a row)
        interpolated, incomplete samples at either end dropped, an export in g
        converted; ``info`` the preamble (``DeviceTag``, ``FirmwareVersion``,
        ``StartTime``, ...) plus ``lost_samples``; ``notes`` what was repaired
        or converted, naming the rows.

    Raises
    ------
    SensorDataError
        Naming the file, row (1-based line number) and column; a gap longer
        than ``MAX_REPAIR_GAP`` samples names its rows.
    """
    path = Path(path)
    lines = read_text(path).rstrip().split("\n")
    h, info = _preamble(path, lines)
    lines, locale = _decimal_commas(lines, h)
    names = tuple(c.strip() for c in lines[h].split(","))
    for column in (CLOCK_COLUMN, *ACC_COLUMNS):
        if column not in names:
            raise _error(path, h + 1, f"'{column}'", f"missing from the header {lines[h]!r}; expected "
                                                     f"{CLOCK_COLUMN} and {', '.join(ACC_COLUMNS)}")
    first_row = h + 2
    if len(lines) - h - 1 < MIN_SAMPLES or not "".join(lines[h + 1:]).strip():
        raise _error(path, first_row, f"'{CLOCK_COLUMN}'",
                     f"{len(lines) - h - 1} data rows; expected at least {MIN_SAMPLES} samples")
    require_table_memory(path, len(lines) - h - 1, len(names))
    names, body, rows, variants = _harmless_variants(names, lines[h + 1:], first_row)
    data = _parse(path, body, names, rows)
    acc = data[:, [names.index(c) for c in ACC_COLUMNS]]
    rates = data[:, [names.index(c) for c in RATE_COLUMNS]] if set(RATE_COLUMNS) <= set(names) else None
    ticks = data[:, names.index(CLOCK_COLUMN)]
    rows_read = rows
    if np.all(acc[0] == 0.0):  # written before the device measures
        acc, ticks, rows = acc[1:], ticks[1:], rows[1:]
        rates = None if rates is None else rates[1:]
    lost, notes = _placeholders(path, acc, ticks, rows)
    notes = locale + variants + notes
    acc, ticks, rows = acc[~lost], ticks[~lost], rows[~lost]
    rates = None if rates is None else rates[~lost]
    if COUNTER_COLUMN in names:
        counter = data[:, names.index(COUNTER_COLUMN)][data.shape[0] - lost.size:][~lost]
        ticks, stamped = _stamps_from_counter(ticks, counter, rows)
        notes += stamped
        _check_clock_step(path, ticks, counter, rows)
    if rows.size < MIN_SAMPLES:
        raise _error(path, first_row, f"'{CLOCK_COLUMN}'", f"{rows.size} rows with measured accelerations; "
                                                          f"expected at least {MIN_SAMPLES} samples")
    absurd = first_absurd(acc)
    if absurd is not None:
        i, j = absurd
        raise _error(path, int(rows[i]), f"'{ACC_COLUMNS[j]}'",
                     f"{float(acc[i, j])!r} m/s^2; expected a finite acceleration of magnitude at most "
                     f"{MAX_ABS_SAMPLE:g} m/s^2 (or an empty cell for a lost sample)")
    index, start, step = _grid(path, ticks, rows)
    full = np.full((int(index[-1]) + 1, 3), np.nan)
    full[index] = acc
    gaps = int(full.shape[0] - index.size)

    dropped = rows_read[data.shape[0] - lost.size:][lost]

    def span(a: int, b: int) -> str:
        """The file rows of grid samples a..b-1 (a lost sample lies between two rows)."""
        inside = rows[(index >= a) & (index < b)]
        before, after = rows[index < a], rows[index >= b]
        if not inside.size and before.size and after.size:
            inside = dropped[(dropped > before[-1]) & (dropped < after[0])]
            if not inside.size:
                return f"the {b - a} sample{'s' if b - a > 1 else ''} lost between rows {before[-1]} and {after[0]}"
        if not inside.size:
            return f"{b - a} samples"
        return f"rows {inside[0]}-{inside[-1]}" if inside.size > 1 else f"row {inside[0]}"

    gone = np.any(np.isnan(full), axis=1)
    full, keep, repaired = repair_missing(full, span, ACC_COLUMNS, str(path))
    acc, units = _units(path, full)
    info = dict(info, lost_samples=gaps + int(lost.sum()))
    time = (start + np.arange(keep.start, keep.stop) * step) / CLOCK_TICKS_PER_SECOND
    if rates is not None:
        on_grid = np.full((gone.size, 3), np.nan)
        on_grid[index] = rates
        rates, dropped_rates = _rates(path, on_grid, gone, keep, span)
        units += dropped_rates
    return SensorRecord(path=path, time=time, step=step / CLOCK_TICKS_PER_SECOND, acc=acc,
                        axes=("X", "Y", "Z"), info=info, notes=tuple(notes + repaired + units), rates=rates)


def _rates(path: Path, on_grid: np.ndarray, gone: np.ndarray, keep: slice, span) -> tuple[np.ndarray | None, list]:
    """The angular rates (rad/s) on the kept accelerations' samples, repaired as they are, or None with a
    note saying why they were dropped (a gap too long, a missing sample at either end of the kept span, a
    wild value); a note for each gap the accelerations did not share."""
    try:
        out, kept, notes = repair_missing(on_grid, span, RATE_COLUMNS, str(path), "angular-rate samples")
    except SensorDataError as err:
        return None, [f"angular rates not read ({err})"]
    if kept.start > keep.start or kept.stop < keep.stop:
        return None, [f"angular rates not read: {', '.join(RATE_COLUMNS)} miss samples at an end of the "
                      f"accelerations' span"]
    out = out[keep.start - kept.start:keep.stop - kept.start]
    if first_absurd(out) is not None or np.nanmax(np.abs(out)) > MAX_RATE:
        return None, [f"angular rates not read: a value beyond {MAX_RATE:g} deg/s (the DOT reads at most 2000)"]
    shared = np.array_equal(np.any(np.isnan(on_grid), axis=1), gone)
    return out * DEGREE, [] if shared else notes


register(ExportFormat(name="xsens-dot", layout=Layout.SENSOR_FILES, read_sensor=read_xsens_dot,
                      description="Xsens DOT CSV export, one file per sensor"))
