"""IMU import: Xsens DOT exports (one file per sensor) with one thing wrong, and folders that
describe them wrongly."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np

from momentid.io.formats.xsens_dot import read_xsens_dot
from momentid.io.importer import import_folder

from ._core import Case, Group, Outcome

PREAMBLE = ("sep=,\nDeviceTag:,Xsens DOT\nFirmwareVersion:,3.0.0\nAppVersion:,2023.6.0\n"
            "StartTime: ,2025-03-06_12:21:16_000 PST\n\u00a9 Movella Technologies B. V. 2005-2025\n\n")
HEADER = "PacketCounter,SampleTimeFine,Euler_X,Euler_Y,Euler_Z,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z"
#: The header is line 8; data rows start on line 9.
FIRST_ROW = 9
#: Device clock step at 120 Hz (us) and the number of rows of a well-formed file.
STEP_US, N_ROWS = 8333, 30


def dot_text(seed: int = 0) -> str:
    """A well-formed export: ``N_ROWS`` rows at 120 Hz, gravity on Z, a small X motion."""
    rng = np.random.default_rng(seed)
    rows = []
    for k in range(N_ROWS):
        ax, ay, az = 0.1 * np.sin(k / 3) + rng.normal(0, 0.01), rng.normal(0, 0.01), 9.81 + rng.normal(0, 0.01)
        rows.append(f"{k},{699806679 + k * STEP_US},0,0,0,{ax:.6f},{ay:.6f},{az:.6f},0,0,0")
    return PREAMBLE + HEADER + "\n" + "\n".join(rows) + "\n"


def _cell(row: int, column: str, value: str) -> str:
    """The good file with the cell of ``column`` on line ``row`` set to ``value``."""
    lines = dot_text().split("\n")
    cells = lines[row - 1].split(",")
    cells[HEADER.split(",").index(column)] = value
    lines[row - 1] = ",".join(cells)
    return "\n".join(lines)


def _both_missing(row: int) -> str:
    """Line ``row`` without its stamp and its packet counter: nothing places it."""
    lines = dot_text().split("\n")
    cells = lines[row - 1].split(",")
    cells[0] = cells[1] = ""
    lines[row - 1] = ",".join(cells)
    return "\n".join(lines)


def _clock(tick):
    """The good file with the device clock of data row ``k`` (0-based) set to ``tick(k)``."""
    lines = dot_text().split("\n")
    for k in range(N_ROWS):
        cells = lines[FIRST_ROW - 1 + k].split(",")
        cells[1] = str(tick(k))
        lines[FIRST_ROW - 1 + k] = ",".join(cells)
    return "\n".join(lines)


def reading(text: str | bytes):
    def act(folder: Path):
        path = folder / "dot.csv"
        path.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8"))
        return read_xsens_dot(path)
    return act


_BAD_FILES = [
    ("acc-1e308", _cell(12, "Acc_X", "1e308"), ("dot.csv", "row 12", "'Acc_X'", "1e+308")),
    ("acc-inf", _cell(13, "Acc_Z", "-inf"), ("dot.csv", "row 13", "'Acc_Z'", "-inf")),
    ("acc-word", _cell(14, "Acc_Y", "g"), ("dot.csv", "row 14", "'Acc_Y'")),
    ("clock-missing-cell-and-counter", _both_missing(15),
     ("dot.csv", "row 15", "'SampleTimeFine'")),
    ("clock-negative", _cell(15, "SampleTimeFine", "-5"), ("dot.csv", "row 15", "'SampleTimeFine'", "-5")),
    ("clock-beyond-uint32", _cell(15, "SampleTimeFine", "1e300"), ("dot.csv", "row 15", "'SampleTimeFine'")),
    ("clock-jitter", _cell(15, "SampleTimeFine", str(699806679 + 6 * STEP_US + 1000)),
     ("dot.csv", "row 15", "'SampleTimeFine'")),
    ("clock-stuck", _clock(lambda k: 699806679), ("dot.csv", "'SampleTimeFine'", "does not advance")),
    ("clock-huge-gap", _clock(lambda k: 699806679 + (k + (400 if k >= 11 else 0)) * STEP_US),
     ("dot.csv", "row 20", "'SampleTimeFine'", "lost")),
    ("no-header", PREAMBLE + "\n".join(dot_text().split("\n")[FIRST_ROW - 1:]), ("dot.csv", "SampleTimeFine")),
    ("header-without-acc", dot_text().replace("Acc_Z", "FreeAcc_Z"), ("dot.csv", "row 8", "'Acc_Z'")),
    ("two-rows", "\n".join(dot_text().split("\n")[:FIRST_ROW + 1]), ("dot.csv", "data rows")),
    ("row-short", "\n".join(line if i != 15 else "7,699864010,0,0" for i, line in enumerate(dot_text().split("\n"))),
     ("dot.csv", "row 16")),
    ("empty-file", "", ("dot.csv",)),
    ("not-utf8", dot_text().encode("utf-8").replace(b"DeviceTag", b"Device\xffTag"), ("dot.csv", "UTF-8")),
    ("broken-gzip", gzip.compress(dot_text().encode())[:60], ("dot.csv", "gzip")),
]

EXPERIMENT = """\
[structure]
storeys = 2
masses = [0.16, 0.16]

[sensors]
format = "xsens-dot"

[[runs]]
name = "sine"
table = "table.csv"
floors = ["f1.csv", "f2.csv"]
"""


def _folder(old: str, new: str):
    assert old in EXPERIMENT, old

    def act(folder: Path):
        lab = folder / "lab"
        lab.mkdir()
        (lab / "experiment.toml").write_text(EXPERIMENT.replace(old, new, 1))
        for name in ("table.csv", "f1.csv", "f2.csv"):
            (lab / name).write_text(dot_text())
        return import_folder(lab)
    return act


_BAD_TOML = [
    ("floors-count", 'floors = ["f1.csv", "f2.csv"]', 'floors = ["f1.csv"]', "floors"),
    ("floor-file-missing", '"f2.csv"]', '"f3.csv"]', "f3.csv"),
    ("table-key-missing", 'table = "table.csv"\n', "", "table"),
    ("floors-not-strings", 'floors = ["f1.csv", "f2.csv"]', "floors = [1, 2]", "floors"),
    ("format-typo", 'format = "xsens-dot"', 'format = "xsens"', "format", "xsens"),
]


def _same_file_twice(folder: Path):
    """Every sensor file holds the same data (a copy-paste slip): refused, not aligned."""
    return _folder('"f2.csv"]', '"f2.csv"]')(folder)


CASES = [Case(Group.IMU, id_, Outcome.ERROR, reading(text), names) for id_, text, names in _BAD_FILES] + [
    Case(Group.IMU, id_, Outcome.ERROR, _folder(old, new), ("experiment.toml", *names))
    for id_, old, new, *names in _BAD_TOML] + [
    Case(Group.IMU, "same-data-in-every-file", Outcome.ERROR, _same_file_twice, (".csv",)),
]
