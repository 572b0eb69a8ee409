"""Reading recordings (:func:`read_recording`, and :func:`stream_recording` block by block): one
streaming pass over the MCAP file that checks every chunk CRC, decodes every sensor block, keeps the
runs that completed and says in notes what a truncated, corrupted or aborted file lost."""

from __future__ import annotations

from collections.abc import Callable
import json
import os
import re
import tomllib
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from google.protobuf import descriptor_pb2
from google.protobuf.message import DecodeError
from mcap.exceptions import RecordLengthLimitExceeded
from mcap.records import Attachment, Channel, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader

from momentid.core.series import Experiment, RunData, channel_unit
from momentid.core.structure import LabStatement, Structure
from momentid.errors import RecordingError, RecoveryWarning, TruncatedRecordingError
from momentid.io.mcap_check import DAMAGE, MCAP_MAGIC, Bounded, summary_damage
from momentid.io.recording_format import (ABORTED_RECORD, EXPERIMENT_RECORD, IMPORT_META_KEYS, READABLE_VERSIONS,
                                          RUN_RECORD, RUN_TOPIC, SCHEMA_NAME, SENSOR_BLOCK_FIELDS, SensorBlock,
                                          check_sample_times)
from momentid.io.structure_table import MASS_RANGE, implausible_mass

__all__ = ["read_recording", "stream_recording"]


@dataclass
class _Run:
    """What the file says about one run while it is being scanned."""

    name: str
    channel_meta: dict | None = None
    channels: tuple[str, ...] | None = None
    blocks: list = field(default_factory=list)  # (first_sample, block_no, time, values)
    record: dict | None = None  # the momentid.run metadata


@dataclass
class _Scan:
    experiment: dict | None = None
    runs: dict = field(default_factory=dict)  # name -> _Run
    channel_runs: dict = field(default_factory=dict)  # channel id -> run name
    channels: dict = field(default_factory=dict)  # channel id -> Channel
    schemas: dict = field(default_factory=dict)  # schema id -> Schema
    models: dict = field(default_factory=dict)  # run name -> model XML
    aborted: dict | None = None
    data_end: bool = False
    data_crc_bad: bool = False
    failure: str | None = None  # where and why the stream stopped early
    at_end: bool = True  # the stream stopped at the end of the file
    on_block: object = None  # streaming: called with each decoded block instead of keeping it


def read_recording(path: str | os.PathLike) -> Experiment:
    """Read a recording written by :class:`~momentid.io.recording.RecordingWriter` (or any writer
    following ``docs/recording-format.md``).

    One streaming pass checks every chunk CRC and decodes every block, so a
    truncated file (no summary or footer) reads like a whole one up to where
    it stops; only runs with their completion record and all samples count.

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file.

    Returns
    -------
    Experiment
        Runs in index order; ``complete`` is False and ``notes`` say what
        was lost when the file was truncated, corrupted or aborted (a
        a :class:`~momentid.errors.RecoveryWarning` repeats every note).

    Raises
    ------
    RecordingError
        The file is missing, not an MCAP file, not a momentid recording, or
        holds inconsistent data (a bad block, clashing run records).
    TruncatedRecordingError
        The file ends early and holds no completed run.
    """
    path = Path(path)
    return _assemble(path, _scan(path))


def stream_recording(path: str | os.PathLike,
                     on_block: Callable[[str, np.ndarray | None, tuple[str, ...], int, np.ndarray, np.ndarray],
                                        object]) -> tuple[dict, list[str], list[str]]:
    """Read a recording block by block without keeping its samples (flat memory).

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file.
    on_block : callable
        ``on_block(run_name, added_mass, channels, first_sample, time, values)`` for every sensor
        block as it is read: ``added_mass`` (d,) kg or None, ``time`` (n,) s, ``values`` (n, c) SI,
        in file order.

    Returns
    -------
    experiment : dict
        The ``momentid.experiment`` metadata (structure and scenario JSON strings).
    complete : list of str
        Runs whose every block arrived and whose completion record was written.
    notes : list of str
        Runs left out and why (the caller must discard what it accumulated for them).
    """
    path = Path(path)

    def hook(run, first, t, v):
        meta = run.channel_meta or {}
        added = np.array(json.loads(meta["added_mass"]), float) if "added_mass" in meta else None
        on_block(run.name, added, run.channels, first, t, v)

    scan = _scan(path, on_block=hook)
    if scan.experiment is None:
        raise RecordingError(f"{path}: no {EXPERIMENT_RECORD!r} metadata record; expected a momentid recording")
    complete, lost = [], []
    for name, run in scan.runs.items():
        rec = run.record
        spans = sorted((b[0], b[4]) for b in run.blocks)
        expected = 0
        ok = rec is not None and rec.get("complete") == "true"
        for first, n in spans:
            ok = ok and first == expected
            expected = first + n
        ok = ok and rec is not None and str(expected) == rec.get("n_samples")
        (complete if ok else lost).append(name if ok else f"run {name!r} is incomplete; left out")
    return scan.experiment, complete, _damage_notes(path, scan, complete, lost)


def _scan(path: Path, on_block=None) -> _Scan:
    try:
        f = open(path, "rb")
    except OSError as e:
        raise RecordingError(f"{path}: cannot open the recording ({e.strerror}); "
                             "expected an existing MCAP file written by momentid") from None
    with f:
        size = os.fstat(f.fileno()).st_size
        magic = f.read(len(MCAP_MAGIC))
        if magic != MCAP_MAGIC:
            if MCAP_MAGIC.startswith(magic):
                raise TruncatedRecordingError(
                    f"{path}: the file ends after {len(magic)} bytes, inside the MCAP magic; "
                    "no completed run to recover")
            raise RecordingError(f"{path}: not an MCAP file (starts with {magic!r}, expected "
                                 f"the MCAP magic {MCAP_MAGIC!r})")
        f.seek(0)
        scan = _Scan(on_block=on_block)
        records = StreamReader(Bounded(f, size), validate_crcs=True, record_size_limit=size).records
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except DAMAGE as e:
                if isinstance(e, CRCValidationError) and isinstance(e.record, DataEnd):
                    scan.data_end, scan.data_crc_bad = True, True
                pos = f.tell()
                why = f"{type(e).__name__}: {e}" if str(e) else type(e).__name__
                scan.failure = f"at byte {pos} of {size} ({why})"
                # A record longer than the rest of the file was cut off, too.
                scan.at_end = pos >= size or isinstance(e, RecordLengthLimitExceeded)
                break
            if isinstance(record, Footer):
                continue
            if isinstance(record, DataEnd):
                scan.data_end = True
            elif not scan.data_end:  # the summary section only repeats what came before
                _take(path, scan, record)
        if scan.data_end and scan.failure is None:
            damage = summary_damage(f, size)
            if damage is not None:
                scan.failure = f"({damage})"
    return scan


def _take(path: Path, scan: _Scan, record) -> None:
    """Fold one data-section record into ``scan``."""
    if isinstance(record, Schema):
        scan.schemas[record.id] = record
    elif isinstance(record, Channel):
        _take_channel(path, scan, record)
    elif isinstance(record, Message):
        name = scan.channel_runs.get(record.channel_id)
        if name is not None:
            _take_block(path, scan.runs[name], record, scan.on_block)
    elif isinstance(record, Metadata):
        if record.name == EXPERIMENT_RECORD:
            if scan.experiment is not None:
                raise RecordingError(f"{path}: a second {EXPERIMENT_RECORD!r} record; expected one")
            scan.experiment = dict(record.metadata)
        elif record.name == RUN_RECORD:
            name = record.metadata.get("name", "")
            if not name:
                raise RecordingError(f"{path}: a {RUN_RECORD!r} record without a name; expected one")
            run = _run(scan, name)
            if run.record is not None:
                raise RecordingError(f"{path}: run {name!r} has two {RUN_RECORD!r} records; expected one")
            run.record = dict(record.metadata)
        elif record.name == ABORTED_RECORD:
            scan.aborted = dict(record.metadata)
    elif isinstance(record, Attachment):
        m = re.fullmatch(r"models/(.+)\.xml", record.name)
        if m:
            scan.models[m.group(1)] = record.data.decode("utf-8", errors="replace")


def _run(scan: _Scan, name: str) -> _Run:
    """The run called ``name``, created on first mention (runs keep file order)."""
    return scan.runs.setdefault(name, _Run(name))


def _take_channel(path: Path, scan: _Scan, ch: Channel) -> None:
    known = scan.channels.get(ch.id)
    if known is not None:
        if known != ch:
            raise RecordingError(f"{path}: channel id {ch.id} is declared twice with different "
                                 f"content ({known.topic!r}, {ch.topic!r}); expected one definition")
        return
    scan.channels[ch.id] = ch
    m = RUN_TOPIC.match(ch.topic)
    if not m:
        return  # other topics are allowed and ignored
    name = m.group(1)
    where = f"{path}: channel {ch.topic!r}"
    schema = scan.schemas.get(ch.schema_id)
    if ch.message_encoding != "protobuf" or schema is None or schema.encoding != "protobuf" \
            or schema.name != SCHEMA_NAME:
        got = (ch.message_encoding, schema.encoding if schema else None, schema.name if schema else None)
        raise RecordingError(f"{where}: (message encoding, schema encoding, schema) = {got!r}; "
                             f"expected ('protobuf', 'protobuf', {SCHEMA_NAME!r})")
    _check_schema(where, schema)
    run = _run(scan, name)
    if run.channel_meta is not None:
        raise RecordingError(f"{where}: a second channel for run {name!r}; expected one per run")
    meta = dict(ch.metadata)
    if meta.get("run", name) != name:
        raise RecordingError(f"{where}: metadata run = {meta['run']!r}; expected {name!r} as in the topic")
    if "channels" in meta:
        run.channels = tuple(meta["channels"].split(","))
        units = meta.get("units")
        want = ",".join(channel_unit(c) for c in run.channels)
        if units is not None and units != want:
            raise RecordingError(f"{where}: metadata units = {units!r}; expected {want!r} "
                                 "(recordings hold SI units)")
    run.channel_meta = meta
    scan.channel_runs[ch.id] = name


def _check_schema(where: str, schema: Schema) -> None:
    """Raise unless the embedded descriptor gives SensorBlock our field layout."""
    try:
        fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    except DecodeError:
        raise RecordingError(f"{where}: schema {SCHEMA_NAME!r} data is not a protobuf "
                             "FileDescriptorSet; expected one") from None
    fields = None
    for fd in fds.file:
        for mt in fd.message_type:
            if fd.package == "momentid" and mt.name == "SensorBlock":
                fields = {f.name: (f.number, f.type, f.label) for f in mt.field}
    for name, number, type_, label in SENSOR_BLOCK_FIELDS:
        if fields is None or fields.get(name) != (number, type_, label):
            got = None if fields is None else fields.get(name)
            raise RecordingError(f"{where}: schema field {name!r} is {got!r}; expected "
                                 f"(number, type, label) = {(number, type_, label)!r}")


def _take_block(path: Path, run: _Run, msg: Message, on_block=None) -> None:
    """Decode and check one SensorBlock; shapes time (n,), values (n, c)."""
    k = len(run.blocks)
    where = f"{path}: run {run.name!r} block {k}"
    try:
        block = SensorBlock.FromString(msg.data)
    except DecodeError as e:
        raise RecordingError(f"{where}: undecodable SensorBlock ({e}); expected {SCHEMA_NAME}") from None
    where += f" (first_sample {block.first_sample})"
    channels = tuple(block.channels)
    if block.run != run.name or (run.channels is not None and channels != run.channels):
        raise RecordingError(f"{where}: run {block.run!r} channels {list(channels)}; expected run "
                             f"{run.name!r} channels {list(run.channels or channels)}")
    run.channels = channels
    t = np.array(block.time, dtype=float)
    v = np.array(block.values, dtype=float)
    n, c = block.n_samples, len(channels)
    if t.shape != (n,) or v.shape != (n * c,):
        raise RecordingError(f"{where}: {t.size} times and {v.size} values; expected n_samples = {n} "
                             f"times and {n} x {c} = {n * c} values")
    check_sample_times(t, where)
    if on_block is not None:   # streaming: hand the block on, keep only where it sits
        on_block(run, block.first_sample, t, v.reshape(n, c))
        run.blocks.append((block.first_sample, k, None, None, n))   # no view: keeps no samples alive
        return
    run.blocks.append((block.first_sample, k, t, v.reshape(n, c)))


def _int(value, where: str, key: str) -> int:
    try:
        return int(value)
    except (TypeError, ValueError):
        raise RecordingError(f"{where}: {key} = {value!r}; expected an integer") from None


def _loads(value, where: str, key: str):
    try:
        return json.loads(value)
    except (TypeError, ValueError):
        raise RecordingError(f"{where}: {key} = {value!r}; expected JSON") from None


def _finish_run(path: Path, run: _Run, storeys: int | None, model_xml: str | None
                ) -> tuple[int, RunData] | str:
    """The run as ``(index, RunData)``, or why it is incomplete."""
    rec = run.record
    if rec is None or rec.get("complete") != "true":
        return f"run {run.name!r} has no {RUN_RECORD!r} completion record"
    where = f"{path}: run {run.name!r}"
    index = _int(rec.get("index"), where, "index")
    meta_index = (run.channel_meta or {}).get("index")
    if meta_index is not None and meta_index != rec["index"]:
        raise RecordingError(f"{where}: channel index {meta_index!r} differs from the completion "
                             f"record's {rec['index']!r}; expected the same")
    n = _int(rec.get("n_samples"), where, "n_samples")
    added = np.array(_loads(rec.get("added_mass"), where, "added_mass"), dtype=float)
    if added.ndim != 1 or (storeys is not None and added.shape[0] != storeys):
        raise RecordingError(f"{where}: added_mass = {rec['added_mass']}; expected a list of "
                             f"{storeys or 'd'} masses (kg)")
    meta_added = (run.channel_meta or {}).get("added_mass")
    if meta_added is not None and not np.array_equal(_loads(meta_added, where, "added_mass"), added):
        raise RecordingError(f"{where}: channel added_mass {meta_added} differs from the completion "
                             f"record's {rec['added_mass']}; expected the same")
    blocks = sorted(run.blocks, key=lambda b: b[0])
    expected = 0
    for first, k, t, _ in blocks:
        if first < expected:
            raise RecordingError(f"{where}: block {k} starts at sample {first}, expected {expected}; "
                                 "blocks overlap")
        if first > expected:
            return f"run {run.name!r} is missing samples {expected}..{first - 1}"
        expected = first + t.shape[0]
    if expected != n:
        return f"run {run.name!r} has {expected} of its {n} samples"
    channels = run.channels or ()
    if "channels" in rec and rec["channels"] != ",".join(channels):
        raise RecordingError(f"{where}: completion record channels = {rec['channels']!r}; expected "
                             f"{','.join(channels)!r} as in its blocks")
    time = np.concatenate([b[2] for b in blocks])
    check_sample_times(time, where)  # across block boundaries
    values = np.concatenate([b[3] for b in blocks])
    meta = {"index": index}
    if model_xml is not None:
        meta["model_xml"] = model_xml
    imported = (run.channel_meta or {}).get("import")
    if imported is not None:
        got = _loads(imported, where, "import")
        if not isinstance(got, dict) or set(got) - set(IMPORT_META_KEYS):
            raise RecordingError(f"{where}: channel import = {imported[:80]!r}; expected a JSON object with "
                                 f"keys among {', '.join(IMPORT_META_KEYS)}")
        meta.update(got)
    return index, RunData(run.name, added, time, channels, values, meta=meta)


def _assemble(path: Path, scan: _Scan) -> Experiment:
    exp = scan.experiment
    if exp is None:
        if scan.failure:
            raise TruncatedRecordingError(
                f"{path}: reading stopped {scan.failure} before the {EXPERIMENT_RECORD!r} record; "
                "no completed run to recover")
        raise RecordingError(f"{path}: not a momentid recording: no {EXPERIMENT_RECORD!r} metadata "
                             "record (expected one, as written by momentid.io.recording)")
    if exp.get("format_version") not in READABLE_VERSIONS:
        raise RecordingError(f"{path}: {EXPERIMENT_RECORD} format_version = "
                             f"{exp.get('format_version')!r}; expected one of "
                             f"{', '.join(repr(v) for v in READABLE_VERSIONS)}")
    where = f"{path}: {EXPERIMENT_RECORD}"
    structure_dict = _loads(exp.get("structure", "null"), where, "structure")
    try:
        structure = None if structure_dict is None else Structure.from_dict(structure_dict)
    except (KeyError, TypeError, ValueError) as e:
        raise RecordingError(f"{where}: structure = {exp['structure']}: {e!r}; expected "
                             "Structure.to_dict() JSON") from None
    storeys = _int(exp["storeys"], where, "storeys") if exp.get("storeys") else None
    if structure is not None and storeys not in (None, structure.storeys):
        raise RecordingError(f"{where}: storeys = {storeys}; expected {structure.storeys} as in the structure")
    storeys = structure.storeys if structure is not None else storeys
    statement = _statement(_loads(exp.get("statement", "null"), where, "statement"), where, exp)
    _plausible_masses(where, structure, statement)
    if statement is not None and storeys not in (None, statement.storeys):
        raise RecordingError(f"{where}: storeys = {storeys}; expected {statement.storeys} as in the statement")
    scenario = _loads(exp.get("scenario", "{}"), where, "scenario")
    if not isinstance(scenario, dict):
        raise RecordingError(f"{where}: scenario = {exp['scenario']}; expected a JSON object")

    done, lost = {}, []
    for run in scan.runs.values():
        got = _finish_run(path, run, storeys, scan.models.get(run.name))
        if isinstance(got, str):
            lost.append(got)
        elif got[0] in done:
            raise RecordingError(f"{path}: runs {done[got[0]].name!r} and {run.name!r} both have "
                                 f"index {got[0]}; expected unique indices")
        else:
            done[got[0]] = got[1]
    runs = tuple(done[i] for i in sorted(done))
    complete = scan.data_end and not scan.data_crc_bad and not lost and scan.aborted is None

    notes = _damage_notes(path, scan, [r.name for r in runs], lost)
    if not complete and not runs:  # notes say why
        raise TruncatedRecordingError(f"{notes[0]}; no completed run to recover")
    for note in notes:
        warnings.warn(note, RecoveryWarning, stacklevel=3)  # points at the caller of read_recording
    return Experiment(runs=runs, structure=structure, scenario=scenario,
                      scenario_text=exp.get("scenario_text", ""), source=str(path),
                      complete=complete, notes=tuple(notes), statement=statement)


def _damage_notes(path: Path, scan: _Scan, kept: list[str], lost: list[str]) -> list[str]:
    """What a damaged or aborted file kept and lost, in the same words for :func:`read_recording` and
    :func:`stream_recording`: ``kept`` names the runs read whole (in file order), ``lost`` says why
    each other run found was left out."""
    recovered = f"recovered {len(kept)} of {len(scan.runs)} runs found"
    if lost:
        recovered += f" ({'; '.join(lost)})"
    planned = _lost_runs(scan.experiment, kept)
    if not scan.data_end:
        what = "truncated" if scan.at_end else "corrupted"
        after = f"after run {kept[-1]!r}" if kept else "before any run completed"
        return [f"{path}: {what} {after}; {recovered}, {planned}; reading stopped {scan.failure}"]
    if scan.data_crc_bad:
        return [f"{path}: data section CRC mismatch ({scan.failure}): a record outside the "
                f"CRC-checked sensor chunks is corrupted; {recovered}"]
    if scan.aborted is not None:
        return [f"{path}: the writer was aborted ({scan.aborted.get('error', '?')}); {recovered}, {planned}"]
    if lost:
        return [f"{path}: {recovered}"]
    if scan.failure:
        return [f"{path}: summary or footer damaged {scan.failure}; all data was read"]
    return []


def _lost_runs(experiment: dict, kept) -> str:
    """Which runs a damaged file lost: the ``[[runs]]`` of the stored scenario (or experiment.toml)
    text that are not in ``kept`` (RunData or names), or "later runs are lost" when it names none."""
    kept = {getattr(r, "name", r) for r in kept}
    try:
        tables = tomllib.loads(experiment.get("scenario_text", "")).get("runs", [])
        planned = [t["name"] for t in tables]
    except (tomllib.TOMLDecodeError, AttributeError, KeyError, TypeError):
        planned = []
    if not planned or not all(isinstance(n, str) for n in planned):
        return "later runs are lost"
    lost = [n for n in planned if n not in kept]
    return f"lost {len(lost)} of the {len(planned)} planned runs ({', '.join(lost) or 'none'})"


def _plausible_masses(where: str, structure: Structure | None, statement: LabStatement | None) -> None:
    """Floor masses outside :data:`~momentid.io.structure_table.MASS_RANGE` (written before imports
    checked them) are refused here, before identification overflows on them or prints K as 0 +- 0."""
    for key, masses in (("structure.masses", structure.masses if structure is not None else None),
                        ("statement.masses", statement.masses if statement is not None else None)):
        bad = None if masses is None else implausible_mass(masses)
        if bad is not None:
            raise RecordingError(f"{where}: {key}[{bad}] = {masses[bad]!r}: expected a floor mass between "
                                 f"{MASS_RANGE[0]:g} and {MASS_RANGE[1]:g} kg (re-import with the masses in kg)")


def _statement(data, where: str, exp: dict) -> LabStatement | None:
    """The ``statement`` JSON back as a :class:`LabStatement` (None when absent or null)."""
    if data is None:
        return None
    try:
        return LabStatement(
            storeys=int(data["storeys"]),
            masses=None if data["masses"] is None else tuple(float(x) for x in data["masses"]),
            storey_heights=(None if data["storey_heights"] is None
                            else tuple(float(x) for x in data["storey_heights"])),
            noise=tuple((str(g), float(v)) for g, v in data["noise"]))
    except (KeyError, TypeError, ValueError) as e:
        raise RecordingError(f"{where}: statement = {exp['statement']}: {e!r}; expected a JSON object with "
                             f"storeys, masses, storey_heights and noise") from None
