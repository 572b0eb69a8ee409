"""Doctored copies of the shipped mini shake-table trials (data/mini_shake_table/): faults a real lab
makes with real, periodic table motion (a sine), where a simulated broadband record would hide them."""

from __future__ import annotations

import gzip
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


CASES = [
    # The table's sensor stops at half its 7307 rows: the run keeps the 3653 samples all four share.
    Case(Group.IMU, "shipped-table-stops-halfway", Outcome.RECOVERY,
         _importing(_table_stops_halfway, check=_no_sensor_reversed), ("kept the 3653 samples every sensor covers",)),
]
