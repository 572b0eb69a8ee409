"""CSV import: a lab folder (``experiment.toml`` + one CSV per run) with one thing wrong."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np

from momentid.io.importer import import_folder

from ._core import Case, Group, Outcome

EXPERIMENT = """\
[experiment]
name = "lab"

[structure]
storeys = 2
masses = [10.0, 12.0]

[[runs]]
name = "r1"
file = "r1.csv"

[[runs]]
name = "r2"
file = "r2.csv"
added_mass = [0.5, 0.5]
"""

#: Rows of a well-formed run file: 20 samples at 100 Hz.
N_ROWS = 20


def csv_text(seed: int = 0) -> str:
    """A well-formed run file: header ``t,zdd,a1,a2`` and ``N_ROWS`` rows of small accelerations."""
    rng = np.random.default_rng(seed)
    rows = [f"{k / 100:.2f},{x:.6f},{y:.6f},{z:.6f}" for k, (x, y, z) in enumerate(rng.normal(0, 0.1, (N_ROWS, 3)))]
    return "t,zdd,a1,a2\n" + "\n".join(rows) + "\n"


def lab_folder(folder: Path, experiment: str = EXPERIMENT, r1: str | bytes | None = None) -> Path:
    """Write the lab folder under ``folder/lab``; ``r1`` replaces run r1's file."""
    lab = folder / "lab"
    lab.mkdir()
    (lab / "experiment.toml").write_text(experiment, encoding="utf-8")
    r1 = csv_text(1) if r1 is None else r1
    (lab / "r1.csv").write_bytes(r1 if isinstance(r1, bytes) else r1.encode("utf-8"))
    (lab / "r2.csv").write_text(csv_text(2), encoding="utf-8")
    return lab


def _line(text: str, row: int, new: str) -> str:
    """``text`` with line ``row`` (1-based) replaced by ``new``."""
    lines = text.split("\n")
    lines[row - 1] = new
    return "\n".join(lines)


def _cell(row: int, column: int, value: str) -> str:
    """The good file with one cell (row 1-based, column 0-based) set to ``value``."""
    text = csv_text(1)
    cells = text.split("\n")[row - 1].split(",")
    cells[column] = value
    return _line(text, row, ",".join(cells))


def _import_csv(r1):
    return lambda folder: import_folder(lab_folder(folder, r1=r1))


def _import_toml(old: str, new: str):
    assert old in EXPERIMENT, old

    def act(folder):
        return import_folder(lab_folder(folder, EXPERIMENT.replace(old, new, 1)))
    return act


#: Run files with one fault: (id, file content, what the message must name).
_BAD_FILES = [
    ("cell-1e308", _cell(5, 2, "1e308"), ("r1.csv", "row 5", "'a1'", "1e+308")),
    ("cell-minus-1e300", _cell(7, 3, "-1e300"), ("r1.csv", "row 7", "'a2'")),
    ("cell-2e6", _cell(4, 1, "2e6"), ("r1.csv", "row 4", "'zdd'", "2000000")),
    ("cell-inf", _cell(6, 1, "inf"), ("r1.csv", "row 6", "'zdd'", "inf")),
    ("cell-word", _cell(3, 2, "abc"), ("r1.csv", "row 3", "'a1'", "'abc'")),
    ("cell-empty", _cell(3, 2, ""), ("r1.csv", "row 3", "'a1'", "empty")),
    ("cell-comma-decimal", _cell(3, 2, "0\u002c5"), ("r1.csv", "row 3")),
    ("cell-hex", _cell(8, 3, "0x1p-3"), ("r1.csv", "row 8", "'a2'")),
    ("row-short", _line(csv_text(1), 9, "0.07,0.1,0.2"), ("r1.csv", "row 9", "'a2'")),
    ("row-long", _line(csv_text(1), 9, "0.07,0.1,0.2,0.3,0.4"), ("r1.csv", "row 9", "extra")),
    ("row-blank", _line(csv_text(1), 9, ""), ("r1.csv", "row 9", "empty line")),
    ("time-backwards", _cell(6, 0, "0.01"), ("r1.csv", "row 6", "'t'")),
    ("time-duplicate", _cell(6, 0, "0.03"), ("r1.csv", "row 6", "'t'")),
    ("time-jump", _cell(20, 0, "0.5"), ("r1.csv", "row 21", "'t'")),
    ("time-nan", _cell(6, 0, "nan"), ("r1.csv", "row 6", "'t'", "nan")),
    ("time-jitter", _cell(10, 0, "0.0851"), ("r1.csv", "row 10", "'t'")),
    ("header-unknown-column", csv_text(1).replace("t,zdd,a1,a2", "t,zdd,a1,a2,gyro"), ("r1.csv", "row 1", "'gyro'")),
    ("header-duplicate", csv_text(1).replace("t,zdd,a1,a2", "t,zdd,a1,a1"), ("r1.csv", "row 1", "'a1'")),
    ("header-missing-a2", csv_text(1).replace("t,zdd,a1,a2", "t,zdd,a1,q1"), ("r1.csv", "'a2'")),
    ("header-missing-time", csv_text(1).replace("t,zdd,a1,a2", "time,zdd,a1,a2"), ("r1.csv", "row 1", "'time'")),
    ("header-q-partial", csv_text(1).replace("t,zdd,a1,a2", "t,zdd,a1,q1"), ("r1.csv", "row 1")),
    ("header-only", "t,zdd,a1,a2\n", ("r1.csv", "0 data rows")),
    ("two-rows", "t,zdd,a1,a2\n0,0,0,0\n0.01,0,0,0\n", ("r1.csv", "2 data rows")),
    ("empty-file", "", ("r1.csv", "empty")),
    ("semicolons", csv_text(1).replace(",", ";"), ("r1.csv", "row 1")),
    ("not-utf8", csv_text(1).encode("utf-8").replace(b"zdd", b"z\xffd"), ("r1.csv", "row 1", "UTF-8")),
    ("broken-gzip", gzip.compress(csv_text(1).encode())[:40], ("r1.csv", "gzip")),
    ("binary-garbage", bytes(range(256)), ("r1.csv",)),
]

#: experiment.toml with one fault: (id, replaced text, replacement, what the message must name).
_BAD_TOML = [
    ("storeys-zero", "storeys = 2", "storeys = 0", "storeys", "0"),
    ("storeys-string", "storeys = 2", 'storeys = "two"', "storeys", "two"),
    ("masses-length", "masses = [10.0, 12.0]", "masses = [10.0]", "masses"),
    ("masses-negative", "masses = [10.0, 12.0]", "masses = [10.0, -12.0]", "masses", "-12"),
    ("format-unknown", "[[runs]]", '[sensors]\nformat = "excel"\n\n[[runs]]', "format", "excel"),
    ("run-file-missing", 'file = "r1.csv"', 'file = "r9.csv"', "r9.csv"),
    ("run-file-absent-key", 'file = "r1.csv"\n', "", "file"),
    ("run-name-duplicate", 'name = "r2"', 'name = "r1"', "r1"),
    ("run-name-empty", 'name = "r2"', 'name = ""', "name"),
    ("added-mass-length", "added_mass = [0.5, 0.5]", "added_mass = [0.5, 0.5, 0.5]", "added_mass"),
    ("added-mass-negative", "added_mass = [0.5, 0.5]", "added_mass = [0.5, -0.5]", "added_mass", "-0.5"),
    ("unknown-key", "[[runs]]", "colour = 3\n\n[[runs]]", "colour"),
    ("toml-syntax", "[experiment]", "[experiment", "line 1"),
    ("no-runs", "[[runs]]\nname = \"r1\"", "[other]\nname = \"r1\"", "other"),
]


def _no_experiment_file(folder: Path):
    lab = lab_folder(folder)
    (lab / "experiment.toml").unlink()
    return import_folder(lab)


def _runs_disagree(folder: Path):
    lab = lab_folder(folder)
    text = "t,zdd,a1,a2\n" + "\n".join(f"{k / 50:.2f},0.1,0.2,0.3" for k in range(N_ROWS))
    (lab / "r2.csv").write_text(text)
    return import_folder(lab)


CASES = [Case(Group.CSV, id_, Outcome.ERROR, _import_csv(text), names) for id_, text, names in _BAD_FILES] + [
    Case(Group.CSV, id_, Outcome.ERROR, _import_toml(old, new), ("experiment.toml", *names))
    for id_, old, new, *names in _BAD_TOML] + [
    Case(Group.CSV, "no-experiment-toml", Outcome.ERROR, _no_experiment_file, ("experiment.toml", "not found")),
    Case(Group.CSV, "not-a-folder", Outcome.ERROR, lambda f: import_folder(f / "nowhere"), ("nowhere",)),
    Case(Group.CSV, "runs-differ-in-rate", Outcome.ERROR, _runs_disagree, ("r2.csv",)),
]
