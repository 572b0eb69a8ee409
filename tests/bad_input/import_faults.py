"""Real exports that are mislabelled, lossy or in the wrong units (issue 18 points 5-6, issue 22 points 2-3
and 6-8): lost packets, units in g, clocks without stamps, decompression bombs, absurd statements, the
same trial twice, swapped sensors; for the Xsens DOT reader, the import of both formats and recordings."""

from __future__ import annotations

import functools
import gzip
import struct
import types
import zlib
from pathlib import Path

import numpy as np

from momentid.core.series import Experiment, RunData
from momentid.core.structure import LabStatement
from momentid.io.formats.xsens_dot import read_xsens_dot
from momentid.io.importer import import_folder
from momentid.io.recording import read_recording, write_experiment

from ._core import Case, Group, Outcome, cli
from .csv_import import EXPERIMENT as CSV_EXPERIMENT, csv_text, lab_folder
from .imu_import import FIRST_ROW, HEADER, N_ROWS, PREAMBLE, STEP_US, dot_text, reading
from .rigs import Rig, Sensors, record, table_motion

#: A three-storey bench-top rig (modes 3.5, 9.7, 14 Hz) recorded 30 s at 120 Hz: long enough for the
#: import's axis detection (6.7 s) and for the sensor-placement check's spectra (12 s).
RIG = Rig(masses=(0.16, 0.16, 0.142), stiffness=(160.0, 160.0, 160.0), damping=0.01)
RATE, SECONDS = 120.0, 30.0


def _notes(experiment: Experiment) -> types.SimpleNamespace:
    """What an import noted, per run and per sensor, as one result with ``notes``."""
    notes = []
    for run in experiment.runs:
        notes += run.meta.get("notes", [])
        for sensor in run.meta.get("sensors", ()):
            notes += sensor["notes"]
    return types.SimpleNamespace(notes=tuple(notes))


# ----------------------------------------------------------------------------- one Xsens file

def _edit_rows(edit) -> str:
    """The 30-row export with ``edit(cells)`` applied to its data rows' cells (a list of lists)."""
    lines = dot_text().split("\n")
    cells = [line.split(",") for line in lines[FIRST_ROW - 1:FIRST_ROW - 1 + N_ROWS]]
    edit(cells)
    return "\n".join(lines[:FIRST_ROW - 1] + [",".join(c) for c in cells] + [""])


def _lost_packet(cells):
    """The Xsens app's mark of a lost packet on data row 10 (line 18): the stamp of row 9 jumps two
    intervals, row 10 repeats it with nan/inf in every channel, PacketCounter runs on."""
    stamp = str(int(cells[9][1]) + STEP_US)
    cells[9][1] = stamp
    cells[10] = [cells[10][0], stamp] + ["nan" if k % 2 else "inf" for k in range(len(cells[10]) - 2)]


def _delete(first: int, count: int):
    return lambda cells: cells.__delitem__(slice(first, first + count))


def _stamp(row: int, value: str):
    def edit(cells):
        cells[row][1] = value
    return edit


def _scale(factor: float):
    def edit(cells):
        for c in cells:
            c[5:8] = [repr(float(x) * factor) for x in c[5:8]]
    return edit


def _counter_wraps(cells):
    """PacketCounter wraps from 65535 to 0 at row 5 and row 12 has no stamp: the counter places it."""
    for k, c in enumerate(cells):
        c[0] = str((65531 + k) % 65536)
    cells[12][1] = ""


def _empty(first: int, count: int):
    def edit(cells):
        for c in cells[first:first + count]:
            c[5:8] = ["", "", ""]
    return edit


def _bomb(folder: Path):
    """A gzip file of a few MB that expands to 2 GB of one repeated row."""
    path = folder / "dot.csv"
    row = ("1,699806679,0,0,0,0.1,0.0,9.81,0,0,0\n" * 30000).encode()
    _write_gzip_bomb(path, (PREAMBLE + HEADER + "\n").encode(), row, 2 * 2 ** 30)
    return read_xsens_dot(path)


def _write_gzip_bomb(path: Path, head: bytes, row: bytes, size: int) -> None:
    """A valid gzip file of ``head`` and then ``row`` repeated to ``size`` bytes (400x smaller on disk).

    ``row`` is deflated once after a full flush (which leaves no back-reference across it and ends on a
    byte), and that block is repeated: the same stream a compressor would write, made in a second rather
    than by deflating 2 GB (13 s).  The trailer's CRC-32 and length are those of the whole expansion.
    """
    packer = zlib.compressobj(9, zlib.DEFLATED, -15)          # raw deflate; the gzip frame written here
    first = packer.compress(head) + packer.flush(zlib.Z_FULL_FLUSH)
    block = packer.compress(row) + packer.flush(zlib.Z_FULL_FLUSH)
    last = packer.flush()                                      # the final (empty) block
    count = size // len(row)
    crc = zlib.crc32(head)
    for _ in range(count):
        crc = zlib.crc32(row, crc)
    with open(path, "wb") as f:
        f.write(b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x02\xff" + first)
        for _ in range(count):
            f.write(block)
        f.write(last + struct.pack("<II", crc, (len(head) + count * len(row)) & 0xFFFFFFFF))


_DOT_CASES = [
    ("lost-packet-row", Outcome.RECOVERY, _edit_rows(_lost_packet),
     ("row 19: no acceleration", "1 lost packet", "repeats the stamp")),
    ("lost-rows-3", Outcome.RECOVERY, _edit_rows(_delete(10, 3)), ("the 3 samples lost between rows 18 and 19",)),
    ("lost-rows-8", Outcome.ERROR, _edit_rows(_delete(10, 8)),
     ("dot.csv", "the 8 samples lost between rows 18 and 19", "8 consecutive samples missing")),
    ("empty-rows-3", Outcome.RECOVERY, _edit_rows(_empty(10, 3)), ("rows 19, 20, 21", "interpolated linearly")),
    ("repeated-stamp", Outcome.ERROR, _edit_rows(_stamp(6, str(699806679 + 5 * STEP_US))),
     ("dot.csv", "row 15", "repeats the stamp of row 14")),
    ("clock-back", Outcome.ERROR, _edit_rows(_stamp(6, str(699806679 + 2 * STEP_US))),
     ("dot.csv", "row 15", "the clock went back")),
    ("stamp-missing", Outcome.RECOVERY, _edit_rows(_stamp(6, "")),
     ("row 15: no SampleTimeFine stamp", "PacketCounter")),
    ("stamp-missing-counter-wrapped", Outcome.RECOVERY, _edit_rows(_counter_wraps),
     ("row 21: no SampleTimeFine stamp", "8333 us per packet")),
    ("units-g", Outcome.RECOVERY, _edit_rows(_scale(1 / 9.80665)), ("accelerations in g", "converted to m/s^2")),
    ("gravity-neither-unit", Outcome.ERROR, _edit_rows(_scale(0.5)), ("dot.csv", "gravity reads 4.9")),
]


# ----------------------------------------------------------------------------- Xsens folders

@functools.cache
def rig_motion(storeys: int, seed: int) -> np.ndarray:
    """Absolute accelerations along the shaking axis (n, 1 + d) of RIG (its first ``storeys`` floors)
    under an earthquake-like table motion: most of it at 0.3-2 Hz, some up to 0.4 x the sample rate."""
    rig = Rig(RIG.masses[:storeys], RIG.stiffness[:storeys], RIG.damping)
    n = int(RATE * SECONDS)
    zdd = table_motion(n, RATE, 0.5, seed, (0.3, 2.0)) + table_motion(n, RATE, 0.1, seed + 1)
    return record(rig, RATE, SECONDS, Sensors(noise=0.005, seed=seed), zdd=zdd)


def dot_export(x: np.ndarray, start_tick: int, seed: int) -> str:
    """An Xsens DOT export of shaking-axis acceleration ``x`` (n,) on X, gravity on Z."""
    rng = np.random.default_rng(seed)
    n = x.size
    y, z = rng.normal(0.0, 0.005, n), 9.81 + rng.normal(0.0, 0.005, n)
    rows = [f"0,{start_tick},0,0,0,0,0,0,0,0,0"]
    rows += [f"{k + 1},{start_tick + (k + 1) * STEP_US},0,0,0,{x[k]:.6f},{y[k]:.6f},{z[k]:.6f},0,0,0" for k in range(n)]
    return PREAMBLE + HEADER + "\n" + "\n".join(rows) + "\n"


IMU_TOML = """\
[structure]
storeys = 3
masses = [0.16, 0.16, 0.142]

[sensors]
format = "xsens-dot"

[[runs]]
name = "run1"
table = "run1_table.csv"
floors = ["run1_f1.csv", "run1_f2.csv", "run1_f3.csv"]

[[runs]]
name = "run2"
table = "run2_table.csv"
floors = ["run2_f1.csv", "run2_f2.csv", "run2_f3.csv"]
"""


def imu_lab(folder: Path, toml: str = IMU_TOML, order=(0, 1, 2, 3), rows: int | None = None,
            copy: bool = False) -> Path:
    """A lab folder of two simulated runs of RIG; run 2's sensors written in ``order`` (a swap: their
    files sit in each other's place), all files cut to ``rows`` samples, run 2 a copy of run 1."""
    lab = folder / "lab"
    lab.mkdir()
    (lab / "experiment.toml").write_text(toml)
    for r, run in enumerate(("run1", "run2")):
        x = rig_motion(3, 0 if copy else r)
        for k, name in enumerate(("table", "f1", "f2", "f3")):
            channel = order[k] if r == 1 else k
            series = x[:rows, channel] if rows else x[:, channel]
            (lab / f"{run}_{name}.csv").write_text(dot_export(series, 1_000_000 * (r + 1), 10 * r + k))
    return lab


def _imu(toml_old: str = "", toml_new: str = "", **kwargs):
    assert toml_old in IMU_TOML

    def act(folder: Path):
        return _notes(import_folder(imu_lab(folder, IMU_TOML.replace(toml_old, toml_new, 1), **kwargs)))
    return act


def _imu_refusing(folder: Path):
    return import_folder(imu_lab(folder, order=(0, 2, 1, 3)), relabel=False)


_IMU_FOLDERS = [
    ("trial-of-10-rows", Outcome.ERROR, _imu(rows=10), ("run1_table.csv", "10 samples", "expected at least 801")),
    ("trial-of-30-rows", Outcome.ERROR, _imu(rows=30), ("run1_table.csv", "30 samples", "0.3-2 Hz")),
    ("storeys-1e9", Outcome.REFUSAL, _imu("storeys = 3\nmasses = [0.16, 0.16, 0.142]", "storeys = 1000000000"),
     ("experiment.toml", "storeys = 1000000000")),
    ("masses-1e308", Outcome.ERROR, _imu("masses = [0.16,", "masses = [1e308,"),
     ("experiment.toml", "masses[0]", "1e+308")),
    ("masses-1e-300", Outcome.ERROR, _imu("masses = [0.16,", "masses = [1e-300,"),
     ("experiment.toml", "masses[0]", "1e-300")),
    ("added-mass-1e12", Outcome.ERROR, _imu('name = "run2"', 'name = "run2"\nadded_mass = 1e12'),
     ("added_mass", "1000000000000")),
    ("same-trial-twice", Outcome.ERROR, _imu('"run2_table.csv"', '"run1_table.csv"'),
     ("experiment.toml", "run1_table.csv", "listed twice")),
    ("copied-trial", Outcome.ERROR, _imu(copy=True), ("run2", "the same data as run 'run1'")),
    ("floors-1-2-swapped", Outcome.RECOVERY, _imu(order=(0, 2, 1, 3)),
     ("run 'run2': the sensors of floor 1 and floor 2 appear swapped", "run2_f2.csv is floor 1's", "relabelled")),
    ("table-and-floor-3-swapped", Outcome.RECOVERY, _imu(order=(3, 1, 2, 0)),
     ("the table's sensor and floor 3's appear swapped",)),
    ("floor-order-reversed", Outcome.RECOVERY, _imu(order=(0, 3, 2, 1)),
     ("the floor order appears reversed", "relabelled")),
    ("floors-swapped-refused", Outcome.ERROR, _imu_refusing, ("experiment.toml", "appear swapped", "refused")),
]


# ----------------------------------------------------------------------------- CSV folders

def _csv_rows(edit):
    """Run r1's file with ``edit(lines)`` applied."""
    def act(folder: Path):
        lines = csv_text(1).split("\n")
        edit(lines)
        return _notes(import_folder(lab_folder(folder, r1="\n".join(lines))))
    return act


def _nan_cells(first: int, count: int, column: int):
    def edit(lines):
        for row in range(first, first + count):
            cells = lines[row - 1].split(",")
            cells[column] = "nan"
            lines[row - 1] = ",".join(cells)
    return edit


def _ms(lines):
    for k in range(1, len(lines)):
        if lines[k]:
            cells = lines[k].split(",")
            cells[0] = f"{float(cells[0]) * 1000:g}"
            lines[k] = ",".join(cells)


def _csv_toml(old: str, new: str, drop: str = ""):
    assert old in CSV_EXPERIMENT and drop in CSV_EXPERIMENT

    def act(folder: Path):
        return _notes(import_folder(lab_folder(folder, CSV_EXPERIMENT.replace(old, new, 1).replace(drop, ""))))
    return act


def _csv_bomb(folder: Path):
    lab = lab_folder(folder)
    _write_gzip_bomb(lab / "r1.csv", b"t,zdd,a1,a2\n", ("0.01,0.1,0.2,0.3\n" * 60000).encode(), 2 * 2 ** 30)
    return import_folder(lab)


def _csv_swapped(folder: Path):
    """Two runs of RIG's first two floors as run files; run r2's a1 and a2 columns swapped."""
    lab = folder / "lab"
    lab.mkdir()
    x = {name: rig_motion(2, seed) for name, seed in (("r1", 0), ("r2", 1))}
    (lab / "experiment.toml").write_text(CSV_EXPERIMENT.replace("[10.0, 12.0]", "[0.16, 0.16]"))
    for name, header in (("r1", "t,zdd,a1,a2"), ("r2", "t,zdd,a2,a1")):
        t = np.arange(x[name].shape[0]) / RATE
        rows = "\n".join(",".join(f"{v:.6f}" for v in (tk, *row)) for tk, row in zip(t, x[name]))
        (lab / f"{name}.csv").write_text(header + "\n" + rows + "\n")
    return _notes(import_folder(lab))


_CSV_CASES = [
    ("nan-cells-3", Outcome.RECOVERY, _csv_rows(_nan_cells(5, 3, 2)),
     ("3 missing samples (rows 5-7) of a1 interpolated linearly",)),
    ("nan-cells-7", Outcome.ERROR, _csv_rows(_nan_cells(5, 7, 2)), ("r1.csv", "rows 5-11", "7 consecutive")),
    ("time-in-ms", Outcome.ERROR, _csv_rows(_ms), ("r1.csv", "sample rate 0.1 Hz", "is the time column in ms?")),
    ("storeys-1e9", Outcome.REFUSAL, _csv_toml("storeys = 2\nmasses = [10.0, 12.0]", "storeys = 1000000000"),
     ("experiment.toml", "storeys = 1000000000")),
    ("storeys-more-than-columns", Outcome.ERROR,
     _csv_toml("storeys = 2\nmasses = [10.0, 12.0]", "storeys = 9", "added_mass = [0.5, 0.5]\n"),
     ("r1.csv", "'a3'", "9 storeys")),
    ("masses-1e308", Outcome.ERROR, _csv_toml("masses = [10.0, 12.0]", "masses = [10.0, 1e308]"),
     ("experiment.toml", "masses[1]", "1e+308")),
    ("masses-1e-300", Outcome.ERROR, _csv_toml("masses = [10.0, 12.0]", "masses = [1e-300, 12.0]"),
     ("experiment.toml", "masses[0]", "1e-300")),
    ("same-file-twice", Outcome.ERROR, _csv_toml('file = "r2.csv"', 'file = "r1.csv"'),
     ("experiment.toml", "r1.csv", "listed twice")),
    ("gzip-bomb", Outcome.ERROR, _csv_bomb, ("r1.csv", "decompression bomb")),
    ("floors-swapped", Outcome.RECOVERY, _csv_swapped,
     ("run 'r2': the sensors of floor 1 and floor 2 appear swapped",)),
]


# ----------------------------------------------------------------------------- recordings

def _recording_with_masses(masses):
    def act(folder: Path):
        run = RunData(name="r", added_mass=np.zeros(2), time=np.arange(100) / 100.0, channels=("zdd", "a1", "a2"),
                      values=np.random.default_rng(0).normal(size=(100, 3)))
        path = folder / "rec.mcap"
        write_experiment(path, Experiment(runs=(run,), statement=LabStatement(storeys=2, masses=masses)))
        return read_recording(path)
    return act


CASES = [Case(Group.IMU, f"dot-{id_}", outcome, reading(text), names) for id_, outcome, text, names in _DOT_CASES] + [
    Case(Group.IMU, "dot-gzip-bomb", Outcome.ERROR, _bomb, ("dot.csv", "decompression bomb")),
    Case(Group.IMU, "dot-gzip-short", Outcome.ERROR, reading(gzip.compress(dot_text().encode())[:-9]),
         ("dot.csv", "broken gzip")),
] + [Case(Group.IMU, id_, outcome, act, names) for id_, outcome, act, names in _IMU_FOLDERS] + [
    Case(Group.CSV, f"import-{id_}", outcome, act, names) for id_, outcome, act, names in _CSV_CASES] + [
    Case(Group.RECORDING, "statement-masses-1e308", Outcome.ERROR, _recording_with_masses((1e308, 1.0)),
         ("rec.mcap", "statement.masses[0]", "1e+308")),
    Case(Group.RECORDING, "statement-masses-1e-300", Outcome.ERROR, _recording_with_masses((1.0, 1e-300)),
         ("rec.mcap", "statement.masses[1]", "1e-300")),
    Case(Group.CLI, "import-refuse-mislabelled", Outcome.REFUSAL,
         lambda folder: cli("import", imu_lab(folder, order=(0, 2, 1, 3)), "-o", folder / "x.mcap",
                            "--refuse-mislabelled"), ("appear swapped", "refused")),
]
