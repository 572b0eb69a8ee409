"""Import of external recordings: a lab's folder of CSV files -> an MCAP recording.

The folder contract (``docs/recording-format.md``, "Importing CSV recordings"):

* ``experiment.toml``: the nominal model the lab believes (``[structure]``:
  ``masses``, ``storey_stiffness``, ``rayleigh_mu``, ``rayleigh_kappa``,
  ``storey_height``, optional ``storeys`` and ``base_mass``), then one
  ``[[runs]]`` table per run with ``file`` (relative to the folder) and
  ``added_mass`` (kg per floor); optional ``[experiment]`` ``name`` and
  ``description``.
* one CSV per run: a header naming the columns ``t``, ``zdd``, ``a1..ad``
  (required), ``q1..qd``, ``v1..vd`` (optional, each group all or none) and
  ``z``, ``zd`` (optional), in any order, then one row per sample in SI units.

Who is to blame decides the error class: a mistake in ``experiment.toml``
(key, type, value, a run file that does not exist) is a
:class:`~momentid.errors.ScenarioError` naming file, key and value, like a
scenario file; a mistake inside a CSV file (header, cell, time column) is a
:class:`~momentid.errors.SensorDataError` naming the file, the row (the
1-based line number in the file, the header is row 1) and the column.

Parsing takes the fast path (``np.loadtxt``, ~0.15 s for 20 s x 1 kHz x 10
columns); only when it fails is the file scanned line by line to name the
first bad row and column.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from momentid.io.toml_reader import Table, load_toml
from momentid.core.series import Experiment, RunData, channel_unit
from momentid.errors import ScenarioError, SensorDataError
from momentid.core.structure import Structure

__all__ = ["import_folder", "import_recording", "write_import", "summary", "read_csv_run",
           "EXPERIMENT_FILE", "TIME_TOLERANCE", "MIN_SAMPLES"]

#: The experiment description every import folder holds.
EXPERIMENT_FILE = "experiment.toml"
#: Largest departure of a time stamp's step (and of the stamp itself) from
#: the uniform clock, as a fraction of the sample interval.  1 % accepts
#: time stamps printed with 6 decimals at 1 kHz (a rounding error of at most
#: 0.1 % of the interval per step) and refuses a dropped sample (100 %) or
#: real clock jitter.
TIME_TOLERANCE = 0.01
#: Fewest samples a run may have (identification's ``check_run`` needs 3).
MIN_SAMPLES = 3
#: Largest relative difference between the sample rates of two runs.
RATE_TOLERANCE = 1e-3


def _header_help(d: int) -> str:
    return (f"t, zdd, a1..a{d} and optionally q1..q{d}, v1..v{d} (each group all or none), z, zd "
            f"(d = {d} storeys from {EXPERIMENT_FILE})")


def _unit(name: str) -> str:
    return "s" if name == "t" else channel_unit(name)


def _csv_error(path: Path, row: int, column: str, message: str) -> SensorDataError:
    """A one-line error about ``column`` (a quoted name or a description) of line ``row``."""
    return SensorDataError(f"{path}: row {row}, column {column}: {message}")


# ----------------------------------------------------------------------------- CSV files

def _read_text(path: Path) -> str:
    try:
        raw = path.read_bytes()
    except IsADirectoryError:
        raise SensorDataError(f"{path}: is a directory; expected a CSV file") from None
    except OSError as e:
        raise SensorDataError(f"{path}: cannot read the file ({e.strerror}); "
                              f"expected a readable CSV file") from None
    try:
        text = raw.decode("utf-8-sig")  # spreadsheet exports often start with a byte-order mark
    except UnicodeDecodeError as e:
        row = raw.count(b"\n", 0, e.start) + 1
        raise SensorDataError(f"{path}: row {row}, byte {e.start}: not UTF-8 text ({e.reason}); "
                              f"expected a plain-text CSV file") from None
    return text.replace("\r\n", "\n")


def _columns(path: Path, header: str, d: int) -> tuple[str, ...]:
    """Validate the header line (row 1) against the vocabulary for ``d`` storeys."""
    groups = {g: tuple(f"{g}{i + 1}" for i in range(d)) for g in ("a", "q", "v")}
    known = {"t", "zdd", "z", "zd", *groups["a"], *groups["q"], *groups["v"]}
    names = tuple(c.strip() for c in header.split(","))
    seen: set[str] = set()
    for j, name in enumerate(names):
        if name not in known:
            what = f"'{name}'" if name else f"{j + 1} (no name)"
            raise _csv_error(path, 1, what, f"unknown column; expected only the columns {_header_help(d)}")
        if name in seen:
            raise _csv_error(path, 1, f"'{name}'", "appears twice in the header; expected each column once")
        seen.add(name)
    for name in ("t", "zdd", *groups["a"]):
        if name not in seen:
            raise _csv_error(path, 1, f"'{name}'", f"missing from the header {header.strip()!r}; expected "
                                                   f"the columns {_header_help(d)}")
    for g in ("q", "v"):
        present = [c for c in groups[g] if c in seen]
        if present and len(present) < d:
            missing = next(c for c in groups[g] if c not in seen)
            raise _csv_error(path, 1, f"'{missing}'", f"missing while {', '.join(present)} are present; "
                                                      f"expected all of {g}1..{g}{d} or none")
    return names


def _parse_slowly(path: Path, rows: list[str], names: tuple[str, ...]) -> np.ndarray:
    """Parse ``rows`` (lines 2.. of the file) cell by cell; raise at the first bad one."""
    out = np.empty((len(rows), len(names)))
    for i, line in enumerate(rows):
        row = i + 2
        if not line.strip():
            raise _csv_error(path, row, f"'{names[0]}'", "empty line; expected one sample per line, "
                                                         "without blank lines between samples")
        fields = line.split(",")
        if len(fields) < len(names):
            raise _csv_error(path, row, f"'{names[len(fields)]}'",
                             f"missing: the row has {len(fields)} fields, expected {len(names)} "
                             f"({','.join(names)})")
        if len(fields) > len(names):
            raise _csv_error(path, row, f"{len(names) + 1} (after '{names[-1]}')",
                             f"extra field {fields[len(names)].strip()!r}: the row has {len(fields)} fields, "
                             f"expected {len(names)} ({','.join(names)})")
        for j, (cell, name) in enumerate(zip(fields, names)):
            text = cell.strip()
            if not text:
                raise _csv_error(path, row, f"'{name}'", f"empty cell; expected a number ({_unit(name)})")
            try:
                out[i, j] = float(text)
            except ValueError:
                raise _csv_error(path, row, f"'{name}'", f"{text!r} is not a number; expected a decimal "
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
        raise _csv_error(path, i + 2, "'t'", f"{float(t[i])!r}; expected a finite time (s)")
    step = np.diff(t)
    back = np.flatnonzero(step <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise _csv_error(path, i + 2, "'t'", f"{float(t[i])!r} s does not increase on row {i + 1} "
                                             f"({float(t[i - 1])!r} s); expected strictly increasing times")
    h = float(np.median(step))
    off = np.flatnonzero(np.abs(step - h) > TIME_TOLERANCE * h)
    if off.size:
        i = int(off[0]) + 1
        raise _csv_error(path, i + 2, "'t'",
                         f"{float(t[i])!r} s is {step[i - 1]:.6g} s after row {i + 1}; expected uniform "
                         f"sampling every {h:.6g} s (within {TIME_TOLERANCE:.0%}): a gap or clock jitter "
                         f"cannot be identified across")
    n = t.size
    grid = t[0] + np.arange(n) * ((t[-1] - t[0]) / (n - 1))
    drift = np.flatnonzero(np.abs(t - grid) > TIME_TOLERANCE * h)
    if drift.size:
        i = int(drift[0])
        raise _csv_error(path, i + 2, "'t'",
                         f"{float(t[i])!r} s is {t[i] - grid[i]:.3g} s off the uniform clock from "
                         f"{float(t[0])!r} s to {float(t[-1])!r} s; expected a steady sample rate")
    return grid


def read_csv_run(path, storeys: int) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
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
        identification to repair or refuse.

    Raises
    ------
    SensorDataError
        Naming the file, the row (1-based line number) and the column.
    """
    path = Path(path)
    text = _read_text(path).rstrip()  # trailing newlines (and spaces) end no row
    if not text:
        raise _csv_error(path, 1, "'t'", f"the file is empty; expected a header row with the columns "
                                         f"{_header_help(storeys)}, then one row per sample")
    header, _, body = text.partition("\n")
    names = _columns(path, header, storeys)
    rows = body.count("\n") + 1 if body else 0
    if rows < MIN_SAMPLES:
        raise _csv_error(path, rows + 2, "'t'", f"{rows} data rows; expected at least {MIN_SAMPLES} samples")
    data = _parse(path, body, names)
    k = names.index("t")
    time = _uniform_time(path, data[:, k])
    inf = np.argwhere(np.isinf(data))
    if inf.size:
        i, j = (int(x) for x in inf[0])
        raise _csv_error(path, i + 2, f"'{names[j]}'", f"{float(data[i, j])!r}; expected a finite number "
                                                       f"(or nan for a missing sample)")
    channels = names[:k] + names[k + 1:]
    values = np.ascontiguousarray(np.delete(data, k, axis=1))
    return time, channels, values


# ----------------------------------------------------------------------------- experiment.toml

@dataclass(frozen=True)
class _RunSpec:
    name: str
    file: Path
    added_mass: tuple[float, ...]


def _structure(tab: Table) -> Structure:
    """The ``[structure]`` table: masses, stiffness, Rayleigh coefficients, heights."""
    masses = tab.numbers("masses", positive=True)
    d = len(masses)
    if tab.integer("storeys", d, minimum=1) != d:
        raise tab.error("storeys", f"the number of entries in 'masses' ({d})")
    out = Structure(
        masses=masses,
        storey_stiffness=tab.numbers("storey_stiffness", length=d, positive=True, scalar_ok=True),
        storey_heights=tab.numbers("storey_height", (0.3,) * d, length=d, positive=True, scalar_ok=True),
        rayleigh_mu=tab.number("rayleigh_mu", nonnegative=True),
        rayleigh_kappa=tab.number("rayleigh_kappa", nonnegative=True),
        base_mass=tab.number("base_mass", 100.0, positive=True),
    )
    tab.finish()
    return out


def _description(folder: Path) -> tuple[dict, Structure, list[_RunSpec], str]:
    """Read ``folder/experiment.toml``: (meta, structure, runs, text)."""
    if not folder.is_dir():
        raise ScenarioError(f"{folder}: not a folder; expected a folder holding {EXPERIMENT_FILE} and "
                            f"one CSV file per run")
    path = folder / EXPERIMENT_FILE
    if not path.is_file():
        raise ScenarioError(f"{path}: file not found; expected {EXPERIMENT_FILE} describing the structure "
                            f"and the runs (docs/recording-format.md, 'Importing CSV recordings')")
    data = load_toml(path)
    text = path.read_text(encoding="utf-8")
    top = Table(data, path)
    meta_tab = top.table("experiment", {})
    meta = {"name": meta_tab.string("name", folder.resolve().name),
            "description": meta_tab.string("description", "")}
    meta_tab.finish()
    structure = _structure(top.table("structure"))
    runs = []
    for tab in top.tables("runs"):
        file = tab.string("file")
        added = tab.numbers("added_mass", length=structure.storeys, nonnegative=True, scalar_ok=True)
        name = tab.string("name", Path(file).stem)
        if not name:
            raise tab.error("name", "a non-empty run name")
        tab.finish()
        csv = folder / file
        if not csv.is_file():
            raise tab.error("file", f"a CSV file, relative to {folder} (looked for {csv})")
        if name in (r.name for r in runs):
            raise tab.error("name" if tab.has("name") else "file",
                            f"a unique run name; {name!r} is already used (default name: the file's stem)")
        runs.append(_RunSpec(name, csv, added))
    top.finish()
    return meta, structure, runs, text


# ----------------------------------------------------------------------------- the import

def import_folder(path) -> Experiment:
    """Read a lab folder (``experiment.toml`` + one CSV per run) into an experiment.

    Parameters
    ----------
    path : str or Path
        The folder; see the module docstring for the contract.

    Returns
    -------
    Experiment
        Runs in ``[[runs]]`` order with channels in each CSV's column order
        (without ``t``); ``structure`` the nominal model of ``[structure]``;
        ``scenario`` a summary with ``name``, ``description``, ``source`` (the
        folder), ``sample_rate`` (Hz), ``duration`` (s, the longest run) and
        ``sensors = {"ideal": False, "set": "imported", "groups": [...]}`` so
        identification treats the data as real measurements;
        ``scenario_text`` the text of ``experiment.toml``.

    Raises
    ------
    ScenarioError
        ``experiment.toml`` is missing or invalid (file, key, value).
    SensorDataError
        A CSV file is malformed (file, row, column), or the runs disagree
        on their channels or sample rate.
    """
    folder = Path(path)
    meta, structure, specs, text = _description(folder)
    runs: list[RunData] = []
    for spec in specs:
        time, channels, values = read_csv_run(spec.file, structure.storeys)
        run = RunData(name=spec.name, added_mass=np.array(spec.added_mass), time=time, channels=channels,
                      values=values, meta={"source_file": str(spec.file)})
        if runs:
            _agree(runs[0], run, specs[0].file, spec.file)
        runs.append(run)
    groups = [g for g in ("zdd", "z", "zd", "a", "q", "v")
              if any(c.rstrip("0123456789") == g for c in runs[0].channels)]
    scenario = {
        "name": meta["name"],
        "description": meta["description"],
        "source": str(folder.resolve()),
        "sample_rate": float(runs[0].sample_rate),
        "duration": float(max(r.time[-1] - r.time[0] for r in runs)),
        "sensors": {"ideal": False, "set": "imported", "groups": groups},
    }
    return Experiment(runs=tuple(runs), structure=structure, scenario=scenario, scenario_text=text,
                      source=str(folder))


def _agree(first: RunData, run: RunData, first_file: Path, file: Path) -> None:
    """Every run records the same channels at the same rate."""
    if set(run.channels) != set(first.channels):
        odd = sorted(set(run.channels) ^ set(first.channels))[0]
        where = "has" if odd in run.channels else "lacks"
        raise _csv_error(file, 1, f"'{odd}'", f"this run {where} it but {first_file.name} does not; expected "
                                              f"every run to record the same channels")
    if abs(run.sample_rate / first.sample_rate - 1) > RATE_TOLERANCE:
        raise _csv_error(file, 3, "'t'", f"sample rate {run.sample_rate:.6g} Hz differs from "
                                         f"{first.sample_rate:.6g} Hz in {first_file.name}; expected every "
                                         f"run sampled at the same rate")


def write_import(experiment: Experiment, out_path) -> Path:
    """Write an imported experiment to the MCAP recording ``out_path`` (folders created)."""
    from momentid.io.recording import write_experiment

    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    return write_experiment(out, experiment)


def import_recording(folder, out_path) -> Path:
    """Import a lab folder (see :func:`import_folder`) and write it to ``out_path``.

    Parameters
    ----------
    folder : str or Path
        The lab's folder: ``experiment.toml`` and the files it names.
    out_path : str or Path
        The MCAP recording to write.

    Returns
    -------
    Path
        ``out_path``, an MCAP recording that :func:`momentid.read_recording`
        reads and :func:`momentid.identify` identifies.
    """
    return write_import(import_folder(folder), out_path)


def summary(experiment: Experiment, out_path) -> str:
    """One line: runs, samples, channels, rate and where the recording went."""
    runs = experiment.runs
    samples = sum(r.n_samples for r in runs)
    return (f"imported {experiment.source}: {len(runs)} runs, {samples} samples, "
            f"{len(runs[0].channels)} channels ({','.join(runs[0].channels)}) at "
            f"{experiment.scenario['sample_rate']:g} Hz -> {out_path}")
