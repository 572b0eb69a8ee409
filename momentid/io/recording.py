"""Recordings: experiments stored as MCAP files with protobuf sensor blocks.

A recording holds one experiment: a ``momentid.experiment`` metadata record
(structure, scenario), then per run one channel ``/runs/<name>/sensors`` whose
messages are :data:`SCHEMA_NAME` blocks of up to ``block_size`` samples, an
optional model attachment and a ``momentid.run`` metadata record that marks
the run complete.  The layout is documented in ``docs/recording-format.md``.

Crash safety: every run is flushed and fsynced before its completion record
is written, so a writer that dies keeps every completed run; the reader
recovers them from a truncated file (see :func:`read_recording`).
"""

from __future__ import annotations

import json
import os
import re
import tomllib
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool
from google.protobuf.message import DecodeError
from google.protobuf.message_factory import GetMessageClass
from mcap.exceptions import RecordLengthLimitExceeded
from mcap.records import Attachment, Channel, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap.writer import CompressionType, Writer

from momentid.core.series import UNITS, Experiment, RunData, channel_unit, json_safe
from momentid.errors import RecordingError, RecoveryWarning, TruncatedRecordingError
from momentid.io.mcap_check import DAMAGE, MCAP_MAGIC, Bounded, summary_damage
from momentid.io.exclusive import open_locked
from momentid.io.structure_table import MASS_RANGE, implausible_mass
from momentid.core.structure import LabStatement, Structure

__all__ = [
    "RecordingWriter",
    "write_experiment",
    "read_recording",
    "FORMAT_VERSION",
    "SCHEMA_NAME",
    "SENSOR_BLOCK_PROTO",
    "SCHEMA_DATA",
    "SensorBlock",
    "run_topic",
]

#: Value of the ``format_version`` key this module writes.  Version 2 added the
#: experiment's ``statement`` and a run channel's ``import`` metadata.
FORMAT_VERSION = "2"
#: Versions this module reads (version 1 files have neither key).
READABLE_VERSIONS = ("1", "2")
#: ``run.meta`` keys of an imported run stored as the channel's ``import`` JSON.
IMPORT_META_KEYS = ("format", "source_file", "source_files", "sensors", "notes")
#: Full protobuf name of the sensor block message (the MCAP schema name).
SCHEMA_NAME = "momentid.SensorBlock"
EXPERIMENT_RECORD = "momentid.experiment"
RUN_RECORD = "momentid.run"
ABORTED_RECORD = "momentid.aborted"

#: The schema as .proto text (documentation; the file embeds the descriptor).
SENSOR_BLOCK_PROTO = """\
syntax = "proto3";
package momentid;

message SensorBlock {
  string run = 1;               // run name
  uint32 first_sample = 2;      // index of the block's first sample in the run
  uint32 n_samples = 3;         // samples in this block
  repeated string channels = 4; // channel names, see docs
  repeated double time = 5;     // packed, shape (n_samples,), s
  repeated double values = 6;   // packed, row-major (n_samples, n_channels), SI units
}
"""

_F = descriptor_pb2.FieldDescriptorProto
#: (name, number, type, label) of every SensorBlock field.
_FIELDS = (
    ("run", 1, _F.TYPE_STRING, _F.LABEL_OPTIONAL),
    ("first_sample", 2, _F.TYPE_UINT32, _F.LABEL_OPTIONAL),
    ("n_samples", 3, _F.TYPE_UINT32, _F.LABEL_OPTIONAL),
    ("channels", 4, _F.TYPE_STRING, _F.LABEL_REPEATED),
    ("time", 5, _F.TYPE_DOUBLE, _F.LABEL_REPEATED),
    ("values", 6, _F.TYPE_DOUBLE, _F.LABEL_REPEATED),
)


def _file_descriptor() -> descriptor_pb2.FileDescriptorProto:
    fdp = descriptor_pb2.FileDescriptorProto(
        name="momentid/sensor_block.proto", package="momentid", syntax="proto3")
    msg = fdp.message_type.add(name="SensorBlock")
    for name, number, type_, label in _FIELDS:
        msg.field.add(name=name, number=number, type=type_, label=label)
    return fdp


_POOL = descriptor_pool.DescriptorPool()
_POOL.Add(_file_descriptor())
#: The generated message class of :data:`SCHEMA_NAME`.
SensorBlock = GetMessageClass(_POOL.FindMessageTypeByName(SCHEMA_NAME))
#: Schema data embedded in every recording: a serialized FileDescriptorSet.
SCHEMA_DATA = descriptor_pb2.FileDescriptorSet(file=[_file_descriptor()]).SerializeToString()


def run_topic(name: str) -> str:
    """MCAP topic of run ``name``'s sensor blocks."""
    return f"/runs/{name}/sensors"


_TOPIC = re.compile(r"^/runs/(.+)/sensors$")


def _varint(x: int) -> bytes:
    out = bytearray()
    while x > 0x7F:
        out.append((x & 0x7F) | 0x80)
        x >>= 7
    out.append(x)
    return bytes(out)


def _encode_block(run: str, first: int, channels, time: np.ndarray, values: np.ndarray) -> bytes:
    """Serialize a SensorBlock; byte-identical to ``SensorBlock(...).SerializeToString()``.

    ``time`` shape (n,) and ``values`` shape (n, c) must be C-contiguous
    little-endian float64.  The packed doubles are appended as raw bytes,
    which is ~50x faster than filling the repeated fields.
    """
    head = SensorBlock(run=run, first_sample=first, n_samples=time.shape[0], channels=channels)
    tb, vb = time.tobytes(), values.tobytes()
    parts = [head.SerializeToString()]
    if tb:  # proto3 omits empty packed fields
        parts += [b"\x2a", _varint(len(tb)), tb]
    if vb:
        parts += [b"\x32", _varint(len(vb)), vb]
    return b"".join(parts)


def _check_times(t: np.ndarray, where: str) -> None:
    """Raise unless ``t`` (shape (n,), s) is finite and strictly increasing."""
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise RecordingError(f"{where}: time[{bad[0]}] = {float(t[bad[0]])!r}; expected finite sample times")
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        i = back[0]
        raise RecordingError(f"{where}: time[{i + 1}] = {float(t[i + 1])!r} follows {float(t[i])!r}; "
                             "expected strictly increasing times")


def _json(value, what: str, path) -> str:
    try:
        return json.dumps(value, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise RecordingError(f"{path}: {what} = {value!r} is not JSON-serializable ({e}); "
                             "expected str, numbers, lists and dicts") from None


class RecordingWriter:
    """Write an experiment run by run; a context manager.

    The header and the ``momentid.experiment`` record are written and
    flushed on construction; each :meth:`write_run` makes its run durable
    before marking it complete.  Leaving the ``with`` block by an exception
    records ``momentid.aborted`` and still finishes the file.

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file to create (overwritten).
    structure : Structure or None
        Nominal model of the rig; fixes the number of storeys ``d`` that
        every run's ``added_mass`` must match.
    scenario : dict
        JSON-serializable scenario summary (``Scenario.summary()``).
    scenario_text : str
        The scenario file's text.
    extra_metadata : dict of str to str, optional
        More keys for the ``momentid.experiment`` record (not read back).
    statement : LabStatement, optional
        What a real lab states short of a nominal model (stored as JSON).
    """

    def __init__(self, path, *, structure: Structure | None, scenario: dict,
                 scenario_text: str = "", extra_metadata: dict[str, str] | None = None,
                 statement: LabStatement | None = None):
        self.path = Path(path)
        self._storeys = (structure.storeys if structure is not None
                         else statement.storeys if statement is not None else None)
        self._runs: list[str] = []  # names of the runs started, in index order
        self._completed = 0
        self._closed = True
        meta = {
            "format_version": FORMAT_VERSION,
            "scenario": _json(scenario, "scenario", self.path),
            "scenario_text": scenario_text,
            "structure": _json(structure.to_dict() if structure is not None else None,
                               "structure", self.path),
            "statement": _json(_statement_dict(statement), "statement", self.path),
            "units": json.dumps(UNITS),
            "storeys": "" if self._storeys is None else str(self._storeys),
        }
        for key, value in (extra_metadata or {}).items():
            if key in meta or not isinstance(key, str) or not isinstance(value, str):
                raise RecordingError(
                    f"{self.path}: extra_metadata key {key!r} = {value!r}: expected a str key other "
                    f"than {', '.join(meta)} and a str value")
            meta[key] = value
        try:   # locked before it is truncated: a second writer of the same file is refused, not mixed in
            self._file = open_locked(self.path)
        except OSError as e:
            raise RecordingError(f"{self.path}: cannot create the recording ({e.strerror}); "
                                 "expected a writable file path") from None
        self._closed = False
        # Uncompressed chunks: float64 sensor data shrink ~10 % with zstd, which halves read speed.
        self._writer = Writer(self._file, compression=CompressionType.NONE, enable_data_crcs=True)
        try:
            self._writer.start(profile="", library="momentid.io.recording format " + FORMAT_VERSION)
            self._schema_id = self._writer.register_schema(SCHEMA_NAME, "protobuf", SCHEMA_DATA)
            self._writer.add_metadata(EXPERIMENT_RECORD, meta)
            self._sync()
        except OSError as e:
            self._abandon()
            raise self._disk_error(e, "the header") from None
        except BaseException:
            self._abandon()
            raise

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc is None:
            self.close()
            return False
        try:
            if not self._closed:
                error = f"{exc_type.__name__}: {exc}" if str(exc) else exc_type.__name__
                self._writer.add_metadata(ABORTED_RECORD, {"error": error,
                                                           "runs_written": str(self._completed)})
            self.close()
        except (OSError, RecordingError):
            # The disk refused more bytes (it is full, say): the completed runs are already fsynced
            # and read back as a truncated file; the error that got us here is the one to report.
            self._abandon()
        return False

    def _abandon(self) -> None:
        """Close the file without writing more (after a write failed)."""
        self._closed = True
        try:
            self._file.close()
        except OSError:
            pass  # the bytes it still held could not be written either; the recovery note says so

    def _disk_error(self, exc: OSError, doing: str) -> RecordingError:
        """A one-line error for a failed write that says what the file still holds."""
        kept = self._runs[:self._completed]
        runs = (f"the {len(kept)} completed run(s) ({', '.join(kept)}) are on disk and read back "
                "with a note" if kept else "no run was completed")
        return RecordingError(f"{self.path}: cannot write {doing} ({exc.strerror or exc}); {runs}; "
                              "expected free space on the disk")

    def _sync(self) -> None:
        self._writer.flush()  # closes the open chunk
        self._file.flush()
        os.fsync(self._file.fileno())

    def write_run(self, run: RunData, *, model_xml: str | None = None, block_size: int = 1000) -> None:
        """Append one run and mark it complete once it is on disk.

        Parameters
        ----------
        run : RunData
            ``time`` shape (n,) s, finite and strictly increasing, n >= 1;
            ``values`` shape (n, c) in SI units; ``added_mass`` shape (d,) kg.
        model_xml : str, optional
            MuJoCo XML of the model that produced the run; stored as the
            attachment ``models/<name>.xml``.
        block_size : int
            Samples per SensorBlock message (1000 keeps messages ~100 kB
            for 10 channels).

        Raises
        ------
        RecordingError
            The writer is closed, the name is empty or already used, or the
            data would not read back (bad times, channel names, added mass), or
            the disk refused the bytes (full: the message names the runs kept).
        """
        try:
            self._write_run(run, model_xml, block_size)
        except OSError as e:  # a full disk, an I/O error
            raise self._disk_error(e, f"run {run.name!r}") from None

    def _write_run(self, run: RunData, model_xml: str | None, block_size: int) -> None:
        where = f"{self.path}: run {run.name!r}"
        if self._closed:
            raise RecordingError(f"{where}: the writer is closed; expected write_run before close()")
        if not run.name or run.name in self._runs:
            raise RecordingError(f"{where}: expected a non-empty run name not already used "
                                 f"(used: {', '.join(self._runs) or 'none'})")
        if not isinstance(block_size, int) or block_size < 1:
            raise RecordingError(f"{where}: block_size = {block_size!r}; expected an int >= 1")
        channels = tuple(run.channels)
        for c in channels:
            if not c or "," in c or channels.count(c) > 1:
                raise RecordingError(f"{where}: channel name {c!r}; expected unique non-empty names "
                                     "without commas")
        t = np.ascontiguousarray(run.time, dtype="<f8")
        n = t.shape[0]
        if t.ndim != 1 or not 1 <= n < 2**32:
            raise RecordingError(f"{where}: time has shape {t.shape}; expected (n,) with 1 <= n < 2**32")
        _check_times(t, where)
        v = np.ascontiguousarray(run.values, dtype="<f8").reshape(n, len(channels))
        added = [float(x) for x in np.asarray(run.added_mass, dtype=float).ravel()]
        if not np.all(np.isfinite(added)) or (self._storeys is not None and len(added) != self._storeys):
            raise RecordingError(f"{where}: added_mass = {added!r}; expected {self._storeys or 'd'} "
                                 "finite masses (kg), one per floor")
        added_json = json.dumps(added)
        index = str(len(self._runs))
        channel_meta = {
            "run": run.name, "index": index, "channels": ",".join(channels),
            "units": ",".join(channel_unit(c) for c in channels), "added_mass": added_json,
        }
        imported = {k: run.meta[k] for k in IMPORT_META_KEYS if k in run.meta}
        if imported:
            channel_meta["import"] = _json(json_safe(imported), "run.meta", where)
        ch_id = self._writer.register_channel(run_topic(run.name), "protobuf", self._schema_id, channel_meta)
        self._runs.append(run.name)  # its topic is taken even if this run fails
        stamps = np.maximum(np.round(t * 1e9), 0)  # log_time: first sample's time in ns
        for k, i in enumerate(range(0, n, block_size)):
            j = min(i + block_size, n)
            data = _encode_block(run.name, i, channels, t[i:j], v[i:j])
            self._writer.add_message(ch_id, int(stamps[i]), data, int(stamps[i]), sequence=k)
        self._writer.flush()
        if model_xml is not None:
            self._writer.add_attachment(int(stamps[0]), int(stamps[0]), f"models/{run.name}.xml",
                                        "application/xml", model_xml.encode("utf-8"))
        self._sync()
        self._writer.add_metadata(RUN_RECORD, {
            "name": run.name, "index": index, "added_mass": added_json, "n_samples": str(n),
            "channels": ",".join(channels), "sample_rate": repr(float(run.sample_rate)),
            "complete": "true",
        })
        self._sync()
        self._completed += 1

    def close(self) -> None:
        """Write the summary and footer and close the file (idempotent)."""
        if self._closed:
            return
        try:
            self._writer.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
        except OSError as e:
            self._abandon()
            raise self._disk_error(e, "the summary and footer") from None
        self._closed = True
        self._file.close()


def write_experiment(path, experiment: Experiment, *, model_xml: dict[str, str] | None = None) -> Path:
    """Write all runs of ``experiment`` to a new recording.

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file to create (overwritten).
    experiment : Experiment
        Runs (with an imported run's ``meta`` keys :data:`IMPORT_META_KEYS`),
        structure, statement, scenario summary and text; ``complete`` and
        ``notes`` are not stored.
    model_xml : dict of str to str, optional
        MuJoCo XML per run name; a run not in it keeps ``run.meta["model_xml"]``
        when present, so reading and rewriting a recording keeps its models.

    Returns
    -------
    Path
        ``path``.
    """
    models = dict(model_xml or {})
    names = {r.name for r in experiment.runs}
    unknown = sorted(set(models) - names)
    if unknown:
        raise RecordingError(f"{path}: model_xml names run {unknown[0]!r}; expected one of "
                             f"{', '.join(sorted(names))}")
    with RecordingWriter(path, structure=experiment.structure, scenario=experiment.scenario,
                         scenario_text=experiment.scenario_text, statement=experiment.statement) as writer:
        for run in experiment.runs:
            writer.write_run(run, model_xml=models.get(run.name, run.meta.get("model_xml")))
    return Path(path)


# ----------------------------------------------------------------------------- reading

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




def read_recording(path) -> Experiment:
    """Read a recording written by :class:`RecordingWriter` (or any writer
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


def stream_recording(path, on_block) -> tuple[dict, list[str], list[str]]:
    """Read a recording block by block without keeping its samples (flat memory).

    Parameters
    ----------
    on_block : callable
        ``on_block(run_name, added_mass, channels, first_sample, time, values)`` for every sensor
        block as it is read: ``time`` (n,) s, ``values`` (n, c) SI, in file order.

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
    m = _TOPIC.match(ch.topic)
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
    for name, number, type_, label in _FIELDS:
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
    _check_times(t, where)
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
    _check_times(time, where)  # across block boundaries
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


def _statement_dict(statement: LabStatement | None) -> dict | None:
    if statement is None:
        return None
    return {"storeys": statement.storeys,
            "masses": None if statement.masses is None else list(statement.masses),
            "storey_heights": None if statement.storey_heights is None else list(statement.storey_heights),
            "noise": [[group, value] for group, value in statement.noise]}


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
