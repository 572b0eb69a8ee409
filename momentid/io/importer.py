"""Import of a lab's raw exports: a folder with ``experiment.toml`` -> an experiment / MCAP recording.

The folder contract (``docs/recording-format.md``, "Importing lab recordings",
and ``docs/real-data.md``):

* ``experiment.toml``: optional ``[experiment]`` ``name`` and ``description``;
  ``[structure]`` what the lab states (``storeys`` and/or ``masses``, optional
  ``storey_height``; with ``storey_stiffness`` and damping a full nominal
  model, :mod:`momentid.io.structure_table`); optional ``[sensors]`` with
  ``format`` (a name in :data:`momentid.io.formats.FORMATS`, default
  ``"csv"``) and ``noise`` (m/s^2 std per channel group); then one
  ``[[runs]]`` table per run: ``name``, optional ``added_mass`` (kg per floor,
  default none) and the run's files, relative to the folder: ``file`` (one
  CSV per run, format ``csv``) or ``table`` and ``floors`` (one file per
  sensor, e.g. ``xsens-dot``).  Files may be gzip-compressed (read by
  content); a named file that exists only as ``<name>.gz`` is read from there.
* a one-file-per-run format is taken as it is (``nan`` cells interpolated, at
  most 5 in a row, with a note); one file per sensor goes through
  :func:`momentid.io.align.align_sensors` (clocks, shaking axis, sign, gravity
  and offset), whose per-sensor reports go into ``run.meta``;
* every run's sensors are checked against physics for their floors
  (:mod:`momentid.io.placement`): relabelled with a note, or refused.

Who is to blame decides the error class: a mistake in ``experiment.toml``
(key, type, value, a run file that does not exist) is a
:class:`~momentid.errors.ScenarioError` naming file, key and value; a mistake
inside a data file is a :class:`~momentid.errors.SensorDataError` naming the
file (and the row and column where there is one).
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass
import os
from pathlib import Path

import numpy as np

from momentid.core.series import TABLE_MOTION, UNITS, Experiment, RunData, run_name_problem
from momentid.core.structure import LabStatement, Structure
from momentid.errors import ScenarioError, SensorDataError
from momentid.io.align import SensorReport, align_sensors
from momentid.io.delays import common_delays
from momentid.io.formats import ExportFormat, Layout, get_format
from momentid.io.formats.base import repair_missing
from momentid.io.formats.csv_run import csv_error, read_csv_run
from momentid.io.placement import check_placement, corrected
from momentid.io.run_checks import check_clipping
from momentid.io.rate import check_model_rate, check_plausible_rate, resonances_near_nyquist
from momentid.io.structure_table import MASS_RANGE, parse_structure
from momentid.io.toml_reader import Table, load_toml

__all__ = ["import_folder", "import_recording", "write_import", "summary", "report", "read_csv_run",
           "EXPERIMENT_FILE", "RATE_TOLERANCE"]

#: The experiment description every import folder holds.
EXPERIMENT_FILE = "experiment.toml"
#: Largest relative difference between the sample rates of two runs.
RATE_TOLERANCE = 1e-3
#: A data file named ``x.csv`` that exists only compressed, as ``x.csv`` + this suffix, is read from there.
GZIP_SUFFIX = ".gz"
#: Format of a folder whose ``experiment.toml`` names none (the original contract).
DEFAULT_FORMAT = "csv"


# ----------------------------------------------------------------------------- experiment.toml

@dataclass(frozen=True)
class _RunSpec:
    name: str
    files: tuple[Path, ...]  # one per run, or the table's then floor 1..d's
    added_mass: tuple[float, ...]


@dataclass(frozen=True)
class _Description:
    meta: dict
    model: Structure | LabStatement
    statement: LabStatement
    fmt: ExportFormat
    runs: list[_RunSpec]
    text: str


def _noise(tab: Table | None) -> tuple[tuple[str, float], ...]:
    """``[sensors] noise = {a = 0.01, zdd = 0.01}``: stated noise std per channel group."""
    if tab is None:
        return ()
    out = tuple((group, tab.number(group, positive=True)) for group in UNITS if tab.has(group))
    tab.finish()
    return out


def _file(tab: Table, key: str, folder: Path, name: str) -> Path:
    """``folder/name``, or its compressed copy ``folder/name.gz`` when only that exists."""
    path = folder / name
    if path.is_file():
        return path
    packed = path.with_name(path.name + GZIP_SUFFIX)
    if packed.is_file():
        return packed
    raise tab.error(key, f"a CSV file (plain or gzip-compressed), relative to {folder} (looked for {path} "
                         f"and {packed.name})")


def _run_files(tab: Table, fmt: ExportFormat, folder: Path, storeys: int) -> tuple[Path, ...]:
    if fmt.layout is Layout.RUN_FILE:
        return (_file(tab, "file", folder, tab.string("file")),)
    floors = tab.strings("floors")
    if len(floors) != storeys:
        raise tab.error("floors", f"{storeys} files, one per floor (floor 1 first), as [structure] states "
                                  f"{storeys} storeys")
    table = _file(tab, "table", folder, tab.string("table"))
    return (table, *(_file(tab, "floors", folder, f) for f in floors))


def _description(folder: Path) -> _Description:
    """Read and check ``folder/experiment.toml``."""
    if not folder.is_dir():
        raise ScenarioError(f"{folder}: not a folder; expected a folder holding {EXPERIMENT_FILE} and "
                            f"the runs' data files")
    path = folder / EXPERIMENT_FILE
    if not path.is_file():
        raise ScenarioError(f"{path}: file not found; expected {EXPERIMENT_FILE} describing the structure "
                            f"and the runs (docs/recording-format.md, 'Importing lab recordings')")
    data = load_toml(path)
    text = path.read_text(encoding="utf-8")
    top = Table(data, path)
    meta_tab = top.table("experiment", {})
    meta = {"name": meta_tab.string("name", folder.resolve().name),
            "description": meta_tab.string("description", "")}
    meta_tab.finish()
    model = parse_structure(top.table("structure"), require_model=False)
    d = model.storeys
    sensors = top.table("sensors", {})
    fmt = get_format(sensors.string("format", DEFAULT_FORMAT), path)
    noise = _noise(sensors.table("noise", None))
    sensors.finish()
    statement = model if isinstance(model, LabStatement) else LabStatement(
        storeys=d, masses=model.masses, storey_heights=model.storey_heights)
    statement = dataclasses.replace(statement, noise=noise)
    runs: list[_RunSpec] = []
    for tab in top.tables("runs"):
        files = _run_files(tab, fmt, folder, d)
        added = tab.numbers("added_mass", None, length=d, nonnegative=True, scalar_ok=True)
        if added is not None and max(added) > MASS_RANGE[1]:
            raise tab.error("added_mass", f"added masses (kg) of at most {MASS_RANGE[1]:g} kg per floor")
        name = tab.string("name", files[0].name.split(".")[0])
        problem = run_name_problem(name)
        if problem:
            raise tab.error("name" if tab.has("name") else "file",
                            f"a run name of one printable line without '/', '\\', '..' or ','; {name!r} has {problem}")
        tab.finish()
        if name in (r.name for r in runs):
            raise tab.error("name" if tab.has("name") else "file",
                            f"a unique run name; {name!r} is already used (default name: the file's stem)")
        _check_not_listed(tab, files, runs)
        runs.append(_RunSpec(name, files, added or (0.0,) * d))
    top.finish()
    return _Description(meta, model, statement, fmt, runs, text)


def _check_not_listed(tab: Table, files: tuple[Path, ...], runs: list[_RunSpec]) -> None:
    """A data file already read for another run (or another sensor of this one): the same trial listed
    twice would validate an identification on its own training data."""
    seen = {f.resolve(): f"run {r.name!r}'s" for r in runs for f in r.files}
    for k, f in enumerate(files):
        if f.resolve() in seen:
            raise tab.error("file" if len(files) == 1 else "table" if k == 0 else "floors",
                            f"files not used twice; {f.name} is already {seen[f.resolve()]} (the same file "
                            f"listed twice?)")
        seen[f.resolve()] = "this run's " + ("table" if k == 0 else f"floor {k}") if len(files) > 1 else "this run's"


# ----------------------------------------------------------------------------- the import

def _read_run_file(spec: _RunSpec, fmt: ExportFormat, storeys: int) -> RunData:
    """One run file as it is, ``nan`` cells interpolated (at most ``MAX_REPAIR_GAP`` in a row) with a note."""
    path = spec.files[0]
    time, channels, values = fmt.read_run(path, storeys)
    check_plausible_rate((time.size - 1) / (time[-1] - time[0]), str(path))

    def rows(a: int, b: int) -> str:  # the header is row 1
        return f"row {a + 2}" if b - a == 1 else f"rows {a + 2}-{b + 1}"

    values, keep, notes = repair_missing(values, rows, channels, str(path))
    return RunData(name=spec.name, added_mass=np.array(spec.added_mass), time=time[keep],
                   channels=channels, values=values, meta={"source_file": str(path), "notes": notes})


@dataclass
class _Sources:
    """What the sensor files of each run gave: ``runs[name] = (spec, records, channels, first)`` with
    ``first`` its alignment without common delays; ``delays`` the common delays applied
    (:func:`common_delays`).  Kept to align a run again once relabelled."""

    runs: dict = dataclasses.field(default_factory=dict)
    delays: dict = dataclasses.field(default_factory=dict)
    motion: tuple = ()


def _read_runs(desc: _Description, storeys: int, sources: _Sources):
    """Every run, in order: a run file as it is, or the sensor files aligned (:func:`align_sensors`),
    twice when the runs agree on a delay of a floor sensor's data behind its stamps
    (:func:`common_delays`): the second time with that delay applied in every run.  ``sources`` gets
    each sensor-file run's records (to realign it once relabelled)."""
    fmt = desc.fmt
    if fmt.layout is Layout.RUN_FILE:
        for spec in desc.runs:
            yield _read_run_file(spec, fmt, storeys)
        return
    channels = ("zdd", *(f"a{i + 1}" for i in range(storeys)))
    seen: dict = {}
    for spec in desc.runs:   # errors of an early run before a later run is read, as one reads them
        records = [fmt.read_sensor(f) for f in spec.files]
        for k, record in enumerate(records):
            _not_copied(record, spec.name, "table" if k == 0 else f"floor {k}", seen)
        sources.runs[spec.name] = (spec, records, channels, align_sensors(records, channels))
    sources.delays = common_delays([s[3] for s in sources.runs.values()], list(sources.runs))
    # the table's other motions that every run's table sensor gives (one set of channels for all runs)
    sources.motion = tuple(c for c in TABLE_MOTION if all(c in s[3].motion for s in sources.runs.values()))
    for spec, records, _, aligned in sources.runs.values():
        if sources.delays:
            aligned = align_sensors(records, channels, sources.delays)
        yield _aligned_run(spec, fmt, channels, aligned, sources.motion)


def _not_copied(record, run: str, role: str, seen: dict) -> None:
    """Refuse a sensor file whose samples a file of another run holds too (a copy saved under another
    name): aligned against sensors it never shook with, it fails to align and blames its clock, or
    passes for evidence it is not.  ``seen`` maps each file's sample digest to its file, run and role.
    (Two files of one run with the same samples are refused by :func:`align_sensors`.)"""
    digest = hashlib.sha256(np.ascontiguousarray(record.time).tobytes() + np.ascontiguousarray(record.acc).tobytes())
    path, other, other_role = seen.setdefault(digest.hexdigest(), (record.path, run, role))
    if other != run:
        raise SensorDataError(f"{record.path}: holds the same samples as {path} (run {other!r}, {other_role}); "
                              f"expected each run's own recordings (a file of another run copied under this "
                              f"run's name?)")


def _aligned_run(spec: _RunSpec, fmt: ExportFormat, channels: tuple, aligned, motion: tuple = ()) -> RunData:
    """The run of sensor files aligned as ``aligned``, checked (clipping, resonances near Nyquist), with the
    table sensor's other motions ``motion`` (of :data:`~momentid.core.series.TABLE_MOTION`) that it has."""
    for j, (ch, f) in enumerate(zip(channels, spec.files)):  # before the placement check reads the shapes
        check_clipping(f"{f}: run {spec.name!r}", ch, aligned.values[:, j])
    notes = list(aligned.notes)
    rate = 1.0 / (aligned.time[1] - aligned.time[0])
    near = resonances_near_nyquist(aligned.values, rate)
    if near:
        notes.append(f"the floors resonate at {', '.join(f'{f:.1f}' for f in near)} Hz, near the Nyquist "
                     f"frequency {rate / 2:.4g} Hz: the sample rate is likely too low for the modes "
                     f"(a mode beyond it folds back)")
    meta = {"format": fmt.name, "source_files": [str(f) for f in spec.files],
            "sensors": [r.to_dict() for r in aligned.reports], "notes": notes}
    extra = tuple(c for c in motion if c in aligned.motion)
    values = np.column_stack([aligned.values, *(aligned.motion[c] for c in extra)])
    return RunData(name=spec.name, added_mass=np.array(spec.added_mass), time=aligned.time,
                   channels=(*channels, *extra), values=values, meta=meta)


def import_folder(path: str | os.PathLike, *, relabel: bool = True) -> Experiment:
    """Read a lab folder (``experiment.toml`` + the runs' data files) into an experiment.

    Parameters
    ----------
    path : str or Path
        The folder; see the module docstring for the contract.
    relabel : bool
        What to do with sensors that physics places on other floors than listed, or finds mounted
        reversed (:mod:`momentid.io.placement`): True (default) relabels or flips them and notes
        it in the run's ``meta["notes"]``; False refuses the import with that note as the error.

    Returns
    -------
    Experiment
        Runs in ``[[runs]]`` order.  A run-file format keeps each file's
        column order (without ``t``); a sensor-file format gives channels
        ``("zdd", "a1", ..., "ad")`` (m/s^2 along the shaking direction,
        sign-corrected, gravity and offset removed, one time base from 0) and
        ``run.meta["sensors"]`` (per-sensor :class:`SensorReport` dicts) and
        ``run.meta["notes"]``.  ``structure`` is the nominal model when
        ``[structure]`` states one, else None; ``statement`` what the lab
        states (storeys, masses, heights, noise).  ``scenario`` a summary with
        ``name``, ``description``, ``source``, ``format``, ``sample_rate``
        (Hz), ``duration`` (s, the longest run) and ``sensors = {"ideal":
        False, "set": "imported", "groups": [...]}`` so identification treats
        the data as real measurements; ``scenario_text`` the text of
        ``experiment.toml``.

    Raises
    ------
    ScenarioError
        ``experiment.toml`` is missing or invalid (file, key, value).
    SensorDataError
        A data file is malformed or unusable (a one-line reason naming the
        file), the runs disagree on their channels or sample rate, or (with
        ``relabel=False``) a sensor sits on another floor than listed.
    """
    folder = Path(path)
    desc = _description(folder)
    d = desc.model.storeys
    structure = desc.model if isinstance(desc.model, Structure) else None
    runs: list[RunData] = []
    sources = _Sources()
    for spec, run in zip(desc.runs, _read_runs(desc, d, sources)):
        if runs:
            _agree(runs[0], run, desc.runs[0].files[0], spec.files[0])
            _not_repeated(runs, run, spec.files[0])
        elif structure is not None:
            check_model_rate(structure, run.sample_rate, str(spec.files[0]))
        runs.append(run)
    runs = _placement(runs, desc, folder / EXPERIMENT_FILE, relabel, sources)
    groups = [g for g in ("zdd", "z", "zd", "a", "q", "v")
              if any(c.rstrip("0123456789") == g for c in runs[0].channels)]
    scenario = {
        "name": desc.meta["name"],
        "description": desc.meta["description"],
        "source": str(folder.resolve()),
        "format": desc.fmt.name,
        "sample_rate": float(runs[0].sample_rate),
        "duration": float(max(r.time[-1] - r.time[0] for r in runs)),
        "sensors": {"ideal": False, "set": "imported", "groups": groups},
    }
    return Experiment(runs=tuple(runs), structure=structure, scenario=scenario, scenario_text=desc.text,
                      source=str(folder), statement=desc.statement)


def _placement(runs: list[RunData], desc: _Description, toml: Path, relabel: bool,
               sources: _Sources) -> list[RunData]:
    """The runs with the sensor-placement check's fixes applied and its findings noted (or refused).

    A relabelled run of sensor files is aligned again from its files in their new roles: the clocks,
    axes and signs were read against the listed table's sensor, which may not be the table's; so were
    the common delays of the floors' data behind their stamps, which are read again over every run in
    its final roles (:func:`_realigned`)."""
    files = {r.name: tuple(r.meta["source_files"]) for r in runs if "source_files" in r.meta}
    findings = check_placement(runs, desc.statement.masses, files)
    if not relabel:
        fixable = next((f for f in findings if f.fixable), None)
        if fixable is not None:
            raise SensorDataError(f"{toml}: {fixable.message}; refused (without --refuse-mislabelled the import "
                                  f"relabels the sensors and notes it)")
    moved = {f.run: f.permutation for f in findings
             if f.fixable and f.permutation is not None and f.run in sources.runs}
    out = {r.name: r for r in runs}
    out.update(_realigned(sources, desc.fmt, moved) if moved else {})
    for finding in findings:
        run = out[finding.run]
        if not finding.fixable:
            out[finding.run] = dataclasses.replace(run, meta=dict(run.meta, notes=[*run.meta.get("notes", ()),
                                                                                   finding.message]))
        elif finding.run in moved:
            note = f"{finding.message}; the files aligned again in these roles: relabelled"
            out[finding.run] = dataclasses.replace(run, meta=dict(run.meta, notes=[*run.meta["notes"], note]))
        else:
            out[finding.run] = corrected(run, finding)
    return [out[r.name] for r in runs]


def _realigned(sources: _Sources, fmt: ExportFormat, moved: dict) -> dict:
    """The runs of sensor files to build again once the runs ``moved`` (name -> permutation of the
    listed files) are relabelled: those runs from their files in the new roles, with the common delays
    read again over every run in its final roles (:func:`common_delays`); every other run too when
    those delays differ from the ones it was aligned with."""
    final = {}
    for name, (spec, records, channels, first) in sources.runs.items():
        if name in moved:
            perm = moved[name]
            spec = _RunSpec(spec.name, tuple(spec.files[p] for p in perm), spec.added_mass)
            records = [records[p] for p in perm]
            first = align_sensors(records, channels)
        final[name] = (spec, records, channels, first)
    delays = common_delays([f[3] for f in final.values()], list(final))
    again = {n for n in final if n in moved or delays != sources.delays}
    return {name: _aligned_run(spec, fmt, channels, align_sensors(records, channels, delays) if delays else first,
                               sources.motion)
            for name, (spec, records, channels, first) in final.items() if name in again}


def _not_repeated(runs: list[RunData], run: RunData, file: Path) -> None:
    """Two runs with identical data (the table's shaking and the floors': the table sensor's other motions
    aside) are the same trial listed twice (copied files): refused, as the copy would count as independent
    evidence and as held-out data for its own fit."""
    def core(r: RunData) -> np.ndarray:
        return r.values[:, [j for j, c in enumerate(r.channels) if c not in TABLE_MOTION]]

    for other in runs:
        if other.values.shape == run.values.shape and np.array_equal(core(other), core(run), equal_nan=True):
            raise SensorDataError(f"{file}: run {run.name!r} holds the same data as run {other.name!r}; expected "
                                  f"each trial once (the same trial listed twice?)")


def _agree(first: RunData, run: RunData, first_file: Path, file: Path) -> None:
    """Every run records the same channels at the same rate."""
    if set(run.channels) != set(first.channels):
        odd = sorted(set(run.channels) ^ set(first.channels))[0]
        where = "has" if odd in run.channels else "lacks"
        raise csv_error(file, 1, f"'{odd}'", f"this run {where} it but {first_file.name} does not; expected "
                                             f"every run to record the same channels")
    if abs(run.sample_rate / first.sample_rate - 1) > RATE_TOLERANCE:
        message = (f"sample rate {run.sample_rate:.6g} Hz differs from {first.sample_rate:.6g} Hz in "
                   f"{first_file.name}; expected every run sampled at the same rate")
        if "sensors" in run.meta:  # aligned sensor files: no single row to blame
            raise SensorDataError(f"{file}: {message}")
        raise csv_error(file, 3, "'t'", message)


def write_import(experiment: Experiment, out_path: str | os.PathLike) -> Path:
    """Write an imported experiment to the MCAP recording ``out_path`` (folders created)."""
    from momentid.io.recording import write_experiment

    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    return write_experiment(out, experiment)


def import_recording(folder: str | os.PathLike, out_path: str | os.PathLike, *, relabel: bool = True) -> Path:
    """Import a lab folder (see :func:`import_folder`) and write it to ``out_path``.

    Parameters
    ----------
    folder : str or Path
        The lab's folder: ``experiment.toml`` and the files it names.
    out_path : str or Path
        The MCAP recording to write.
    relabel : bool
        As in :func:`import_folder`: relabel sensors physics places on other floors (default), or
        refuse.

    Returns
    -------
    Path
        ``out_path``, an MCAP recording that :func:`momentid.read_recording`
        reads and :func:`momentid.identify` identifies.
    """
    return write_import(import_folder(folder, relabel=relabel), out_path)


def report(experiment: Experiment) -> list[str]:
    """Per run, what the import did with each sensor and any note (runs of a run-file format: their
    notes only)."""
    lines = []
    for run in experiment.runs:
        sensors = run.meta.get("sensors") or ()
        notes = run.meta.get("notes", ())
        if not sensors and not notes:
            continue
        lines.append(f"run {run.name!r}: {run.n_samples} samples, {run.time[-1] - run.time[0]:.2f} s")
        lines += [f"  {SensorReport.from_dict(s).line()}" for s in sensors]
        lines += [f"  note: {n}" for n in notes]
    return lines


def summary(experiment: Experiment, out_path: str | os.PathLike) -> str:
    """One line: runs, samples, channels, rate and where the recording went."""
    runs = experiment.runs
    samples = sum(r.n_samples for r in runs)
    return (f"imported {experiment.source}: {len(runs)} runs, {samples} samples, "
            f"{len(runs[0].channels)} channels ({','.join(runs[0].channels)}) at "
            f"{experiment.scenario['sample_rate']:g} Hz -> {out_path}")
