"""Doctored copies of the shipped mini shake-table trials (data/mini_shake_table/): faults a real lab
makes with real, periodic table motion (a sine), where a simulated broadband record would hide them."""

from __future__ import annotations

import gzip
import re
from pathlib import Path

import numpy as np

from momentid.io.importer import import_folder

from ._core import Case, Group, Outcome
from .import_faults import _notes

SHIPPED = Path(__file__).resolve().parents[2] / "data" / "mini_shake_table" / "flexible_3storey"
#: The sine 1.5 trial: table, floors 1-3 (160 s at 120 Hz; a 1.5 Hz sine after a 15.6 s quiet lead-in).
TRIAL = ("Ground Floor/(Sine 1.5)Xsens DOT_20250306_121949.csv.gz",
         "1st Floor/(Sine 1.5)Xsens DOT_20250306_121949.csv.gz",
         "2nd Floor/(Sine 1.5)left leg_20250306_121949.csv.gz",
         "3rd Floor (Top floor)/(Sine 1.5)Xsens DOT_20250306_121949.csv.gz")
NAMES = ("table.csv", "f1.csv", "f2.csv", "f3.csv")
TOML = """\
[structure]
storeys = 3
masses = [0.160, 0.160, 0.142]

[sensors]
format = "xsens-dot"

[[runs]]
name = "sine_1p5"
table = "table.csv"
floors = ["f1.csv", "f2.csv", "f3.csv"]
"""
#: Xsens DOT columns: the data rows start after the header line ``PacketCounter,...``.
ACC_X = 5


def shipped_lab(folder: Path, edit=None, toml: str = TOML) -> Path:
    """The sine 1.5 trial as plain files in ``folder/lab``; ``edit(k, header, rows)`` may change
    sensor ``k``'s (0: table) header lines and data rows (lists of str) in place."""
    lab = folder / "lab"
    lab.mkdir()
    (lab / "experiment.toml").write_text(toml)
    for k, (source, name) in enumerate(zip(TRIAL, NAMES)):
        lines = gzip.decompress((SHIPPED / source).read_bytes()).decode("utf-8").splitlines()
        first = next(i for i, line in enumerate(lines) if line.startswith("PacketCounter")) + 1
        header, rows = lines[:first], [line for line in lines[first:] if line]
        if edit is not None:
            edit(k, header, rows)
        (lab / name).write_text("\n".join(header + rows) + "\n")
    return lab


def _importing(edit, toml: str = TOML, check=None):
    def act(folder: Path):
        experiment = import_folder(shipped_lab(folder, edit, toml))
        if check is not None:
            check(experiment)
        return _notes(experiment)
    return act


def _table_stops_halfway(k, header, rows):
    if k == 0:
        del rows[len(rows) // 2:]


def _no_sensor_reversed(experiment):
    """Every shipped sensor is mounted the right way round: a flip is a wrong answer."""
    flipped = [s["channel"] for s in experiment.runs[0].meta["sensors"] if s["sign"] < 0]
    if flipped:
        raise AssertionError(f"sensors {flipped} flipped: the table stopping early misaligned them")


def _clock_fast(ppm: float):
    """Floor 3's device samples ``ppm`` faster than its stamps say: its data are the shipped
    samples read at ``k (1 + ppm 1e-6)`` (linear interpolation) under the same stamps."""
    def edit(k, header, rows):
        if k != 3:
            return
        cells = np.array([[float(c) for c in row.split(",")] for row in rows])
        n = np.arange(len(rows), dtype=float)
        for j in range(ACC_X, ACC_X + 3):
            cells[:, j] = np.interp(n * (1 + ppm * 1e-6), n, cells[:, j])
        rows[:] = [",".join(row.split(",")[:ACC_X] + [f"{v:.8f}" for v in c[ACC_X:ACC_X + 3]]
                            + row.split(",")[ACC_X + 3:])
                   for row, c in zip(rows, cells)]
    return edit


def _drift_read(ppm: float):
    """Floor 3's note gives the drift to 15 % (the floors' own phase moves the lag read in 10 s
    windows by up to 0.6 samples on the shipped trials, of the 1.4 samples 300 ppm adds there);
    no other sensor is resampled."""
    def check(experiment):
        notes = {s["channel"]: " ".join(s["notes"]) for s in experiment.runs[0].meta["sensors"]}
        found = re.search(r"drifts from the table's by ([-+]\d+) ppm", notes["a3"])
        if (found is None or abs(-float(found.group(1)) / ppm - 1) > 0.15
                or any("drifts" in notes[c] for c in ("a1", "a2"))):
            raise AssertionError(f"drift {ppm} ppm on a3 read as: {notes}")
    return check


def _on(sensor: int, edit):
    """``edit`` (written for floor 3) applied to ``sensor`` (0: the table) instead."""
    def moved(k, header, rows):
        if k == sensor:
            edit(3, header, rows)
    return moved


def _drifts(expected: dict, within: float = 0.05):
    """Each sensor's note gives its drift (ppm) within ``within`` of ``expected`` (channel -> ppm; the
    others: no drift).  5 %: the windowed lag, read again after each resampling, lands within 3 % of
    1700-5000 ppm on this trial; a sensor corrected by a constant shift instead reads no drift at all."""
    def check(experiment):
        notes = {s["channel"]: " ".join(s["notes"]) for s in experiment.runs[0].meta["sensors"]}
        for ch in ("a1", "a2", "a3"):
            found = re.search(r"drifts from the table's by ([-+]\d+) ppm", notes[ch])
            want = expected.get(ch)
            if (want is None) != (found is None) or (want and abs(float(found.group(1)) / want - 1) > within):
                raise AssertionError(f"expected drifts {expected} ppm, read: {notes}")
    return check


def _stamps_slow(ppm: float):
    """Floor 3's device samples ``ppm`` slower and its stamps say so (8347 us for 1680 ppm)."""
    data = _clock_fast(ppm)

    def edit(k, header, rows):
        if k != 3:
            return
        data(k, header, rows)
        cells = [row.split(",") for row in rows]
        t0 = int(cells[0][1])
        for c in cells:
            c[1] = str(int(round(t0 + (int(c[1]) - t0) * (1 + ppm * 1e-6))))
        rows[:] = [",".join(c) for c in cells]
    return edit


def _starts_late(k, header, rows):
    """Floor 3's file starts 30 s late (switched on late): 3600 rows fewer at its start."""
    if k == 3:
        del rows[:3600]


def _decimal_commas(k, header, rows):
    """Floor 2's export written in a locale with decimal commas: cells separated by ';'."""
    if k == 2:
        header[:] = [line.replace(",", ";") for line in header]
        rows[:] = [row.replace(",", ";").replace(".", ",") for row in rows]


def _same_as_clean(experiment):
    """The decimal-comma file reads exactly as the shipped one."""
    clean_folder = Path(experiment.runs[0].meta["source_files"][0]).parents[1] / "clean"
    clean_folder.mkdir()
    clean = import_folder(shipped_lab(clean_folder))
    if not np.array_equal(experiment.runs[0].values, clean.runs[0].values):
        raise AssertionError("the decimal-comma export reads differently from the shipped one")


def _clipped(k, header, rows):
    """Floor 3's accelerometer saturates at +-1 m/s^2 on its shaking axis (X)."""
    if k == 3:
        def clip(row):
            cells = row.split(",")
            cells[ACC_X] = f"{min(max(float(cells[ACC_X]), -1.0), 1.0):.8f}"
            return ",".join(cells)
        rows[:] = [clip(row) for row in rows]


def _clock_step(k, header, rows):
    """Floor 1's device clock steps +50 ms halfway (a re-synchronisation); PacketCounter runs on."""
    if k == 1:
        for i in range(len(rows) // 2, len(rows)):
            cells = rows[i].split(",")
            cells[1] = str(int(cells[1]) + 50_000)
            rows[i] = ",".join(cells)


def _duplicated_row(k, header, rows):
    """Floor 2's export writes its row 500 twice (an exactly duplicated line)."""
    if k == 2:
        rows.insert(501, rows[500])


def _trailing_commas(k, header, rows):
    """Floor 2's export ends every data row in a comma (an empty cell beyond the header's columns)."""
    if k == 2:
        rows[:] = [row + "," for row in rows]


CASES = [
    # The table's sensor stops at half its 7307 rows: the run keeps the 3653 samples all four share.
    Case(Group.IMU, "shipped-table-stops-halfway", Outcome.RECOVERY,
         _importing(_table_stops_halfway, check=_no_sensor_reversed), ("kept the 3653 samples every sensor covers",)),
    # Floor 3's clock 300 ppm fast: over the 40 s of shaking its lag to the table grows 1.4 samples.
    Case(Group.IMU, "shipped-clock-drift-300ppm", Outcome.RECOVERY,
         _importing(_clock_fast(300), check=_drift_read(300)),
         ("its clock drifts from the table's by", "ppm", "resampled onto the table's clock")),
    # One file listed for floors 1 and 2: the message used to read "already run 'this run''s".
    Case(Group.IMU, "shipped-one-file-two-floors", Outcome.ERROR,
         _importing(None, TOML.replace('"f1.csv", "f2.csv"', '"f1.csv", "f1.csv"')),
         ("experiment.toml", "runs[0].floors", "f1.csv is already this run's floor 1")),
    # A decimal-comma locale's export: 'missing from the header' used to name a column it holds.
    Case(Group.IMU, "shipped-decimal-commas", Outcome.RECOVERY, _importing(_decimal_commas, check=_same_as_clean),
         ("cells separated by ';' with decimal commas",)),
    # A saturated floor sensor: import used to read its clipped shape as floors 2 and 3 swapped, and relabel.
    Case(Group.IMU, "shipped-floor-clipped", Outcome.ERROR, _importing(_clipped),
         ("f3.csv", "channel a3 is clipped", "consecutive samples at")),
    # Issue 32: drifts of 1700-5000 ppm with agreeing stamps were read as a constant shift ("aligned from the
    # data", a lag running from +2.2 to -1.1 samples); a drifting table sensor was corrected on one floor only.
    Case(Group.IMU, "shipped-clock-drift-1700ppm", Outcome.RECOVERY,
         _importing(_clock_fast(1700), check=_drifts({"a3": -1700})), ("resampled onto the table's clock",)),
    Case(Group.IMU, "shipped-clock-drift-minus-5000ppm", Outcome.RECOVERY,
         _importing(_clock_fast(-5000), check=_drifts({"a3": 5000})), ("resampled onto the table's clock",)),
    Case(Group.IMU, "shipped-table-clock-drift-1711ppm", Outcome.RECOVERY,
         _importing(_on(0, _clock_fast(1711)), check=_drifts({"a1": 1711, "a2": 1711, "a3": 1711})),
         ("resampled onto the table's clock",)),
    # A device whose stamps give its own rate (8347 us against 8333 us) was refused as "sensors at different rates".
    Case(Group.IMU, "shipped-stamps-give-own-rate", Outcome.RECOVERY,
         _importing(_stamps_slow(1680), check=_drifts({})), ("8347.", "+1680 ppm", "resampled onto the table's clock")),
    # A floor file that starts 30 s late got an invented drift of -284 ppm and ended 1.8 samples off.
    Case(Group.IMU, "shipped-floor-starts-late", Outcome.RECOVERY,
         _importing(_starts_late, check=_drifts({})), ("kept the",)),
    # No masses stated (they are optional) and floors 1 and 2 listed swapped: the relabelling used to crash
    # with "object of type 'NoneType' has no len()" (issue 32).
    Case(Group.IMU, "shipped-swapped-without-masses", Outcome.RECOVERY,
         _importing(None, TOML.replace("masses = [0.160, 0.160, 0.142]\n", "").replace(
             '"f1.csv", "f2.csv"', '"f2.csv", "f1.csv"')),
         ("appear swapped",)),
    # Issue 32: harmless export variants were refused ("repeats the stamp of row 509", "the row has 12
    # fields, expected 11"); they read exactly as the shipped file, with a note.
    Case(Group.IMU, "shipped-duplicated-row", Outcome.RECOVERY, _importing(_duplicated_row, check=_same_as_clean),
         ("row 510: repeat(s) an earlier row exactly", "dropped")),
    Case(Group.IMU, "shipped-trailing-commas", Outcome.RECOVERY, _importing(_trailing_commas, check=_same_as_clean),
         ("every data row (rows 9-7316) ends in a comma", "ignored")),
    # A clock step with the packet counter running on used to be named "6 samples lost".
    Case(Group.IMU, "shipped-clock-step", Outcome.ERROR, _importing(_clock_step),
         ("f1.csv", "'SampleTimeFine'", "the device clock stepped +50.0 ms and no packet was lost")),
]
