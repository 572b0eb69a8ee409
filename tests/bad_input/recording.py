"""Recordings (MCAP): files cut short, bytes flipped, records missing or contradicting each other."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
from mcap.writer import Writer

from momentid.core.series import Experiment, RunData
from momentid.core.structure import Structure
from momentid.io.recording import SCHEMA_DATA, SCHEMA_NAME, RecordingWriter, SensorBlock, read_recording

from ._core import Case, Group, Outcome

CHANNELS = ("zdd", "a1", "a2")
STRUCTURE = Structure(masses=(10.0, 12.0), storey_stiffness=(2000.0, 1500.0), storey_heights=(0.3, 0.3),
                      rayleigh_mu=0.05, rayleigh_kappa=1e-3)
#: Samples per run; 250 with the writer's 1000-sample blocks: one chunk per run.
N_SAMPLES = 250


def run(i: int) -> RunData:
    """Run ``r<i>``: seeded noise at 200 Hz."""
    values = np.random.default_rng(i).normal(0.0, 0.1, (N_SAMPLES, len(CHANNELS)))
    return RunData(f"r{i}", np.array([0.1 * i, 0.1 * i]), np.arange(N_SAMPLES) / 200.0, CHANNELS, values)


def tiny_experiment(n_runs: int = 2) -> Experiment:
    """Runs r1.. of :func:`run` on the two-storey ``STRUCTURE``."""
    return Experiment(tuple(run(i + 1) for i in range(n_runs)), STRUCTURE, {"name": "tiny"}, "")


def good(folder: Path, n_runs: int = 3) -> tuple[Path, list[int]]:
    """A well-formed recording and the file size after each completed run."""
    path = folder / "rec.mcap"
    sizes = []
    with RecordingWriter(path, structure=STRUCTURE, scenario={"name": "bad"}) as writer:
        for i in range(n_runs):
            writer.write_run(run(i + 1))
            sizes.append(path.stat().st_size)
    return path, sizes


def _read(mangle):
    """Write a good recording, ``mangle(data, sizes) -> bytes`` it, read it back."""
    def act(folder: Path):
        path, sizes = good(folder)
        path.write_bytes(mangle(path.read_bytes(), sizes))
        return read_recording(path)
    return act


def _flip(data: bytes, at: int) -> bytes:
    out = bytearray(data)
    out[at] ^= 0xFF
    return bytes(out)


def _footer(data: bytes) -> int:
    """Offset of the footer record (29 bytes) before the closing 8-byte magic."""
    return len(data) - 8 - 29


def _summary_start(data: bytes) -> int:
    return struct.unpack_from("<Q", data, _footer(data) + 9)[0]


def _summary_record(data: bytes, opcode: int) -> int:
    """Offset of the first summary record with ``opcode`` (0x08 chunk index, 0x0D metadata index)."""
    at = _summary_start(data)
    while data[at] != opcode:
        at += 9 + struct.unpack_from("<Q", data, at + 1)[0]
    return at


#: Mangled files: (id, outcome, mangle(data, sizes), what the message must name).
_MANGLED = [
    ("cut-after-run-1", Outcome.RECOVERY, lambda d, s: d[:s[0]], ("rec.mcap", "truncated after run 'r1'")),
    ("cut-after-run-2", Outcome.RECOVERY, lambda d, s: d[:s[1]], ("rec.mcap", "truncated after run 'r2'")),
    ("cut-inside-run-2", Outcome.RECOVERY, lambda d, s: d[:(s[0] + s[1]) // 2], ("rec.mcap", "truncated", "r1")),
    ("cut-inside-run-3", Outcome.RECOVERY, lambda d, s: d[:(s[1] + s[2]) // 2], ("rec.mcap", "2 of")),
    ("cut-in-summary", Outcome.RECOVERY, lambda d, s: d[:len(d) - 40], ("rec.mcap", "summary or footer damaged")),
    ("cut-inside-run-1", Outcome.ERROR, lambda d, s: d[:s[0] // 2], ("rec.mcap", "no completed run")),
    ("cut-inside-magic", Outcome.ERROR, lambda d, s: d[:5], ("rec.mcap", "5 bytes")),
    ("empty-file", Outcome.ERROR, lambda d, s: b"", ("rec.mcap", "0 bytes")),
    ("flip-in-run-2-data", Outcome.RECOVERY, lambda d, s: _flip(d, (s[0] + s[1]) // 2),
     ("rec.mcap", "corrupted after run 'r1'")),
    ("flip-in-run-3-data", Outcome.RECOVERY, lambda d, s: _flip(d, (s[1] + s[2]) // 2),
     ("rec.mcap", "corrupted after run 'r2'")),
    ("flip-in-run-1-data", Outcome.ERROR, lambda d, s: _flip(d, s[0] // 2), ("rec.mcap", "no completed run")),
    ("footer-crc", Outcome.RECOVERY, lambda d, s: _flip(d, _footer(d) + 25), ("rec.mcap", "summary CRC")),
    ("chunk-index", Outcome.RECOVERY, lambda d, s: _flip(d, _summary_record(d, 0x08) + 30),
     ("rec.mcap", "summary or footer damaged")),
    ("metadata-index", Outcome.RECOVERY, lambda d, s: _flip(d, _summary_record(d, 0x0D) + 12),
     ("rec.mcap", "summary or footer damaged")),
    ("closing-magic", Outcome.RECOVERY, lambda d, s: d[:-8] + b"NOTMCAP!", ("rec.mcap", "footer")),
    ("not-mcap", Outcome.ERROR, lambda d, s: b"PK\x03\x04 a zip file, say" + d, ("rec.mcap", "not an MCAP file")),
    ("random-bytes", Outcome.ERROR, lambda d, s: np.random.default_rng(0).bytes(4096), ("rec.mcap", "not an MCAP")),
]


def _aborted(folder: Path):
    path = folder / "rec.mcap"
    try:
        with RecordingWriter(path, structure=STRUCTURE, scenario={}) as writer:
            writer.write_run(run(1))
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        pass
    return read_recording(path)


def raw(folder: Path, *, experiment=None, runs=None, schema=(SCHEMA_NAME, "protobuf", SCHEMA_DATA),
        encoding="protobuf", block=None, channel_meta=None) -> Path:
    """A recording written by the stock MCAP writer with one run 'r1' of 4 samples; every record
    can be replaced to contradict the others."""
    path = folder / "raw.mcap"
    t = np.arange(4) * 0.01
    block = block or dict(run="r1", first_sample=0, n_samples=4, channels=("zdd", "a1"), time=t, values=np.zeros(8))
    record = {"name": "r1", "index": "0", "added_mass": "[0.5]", "n_samples": "4", "complete": "true"}
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start()
        schema_id = writer.register_schema(*schema)
        writer.add_metadata("momentid.experiment", {"format_version": "2", "storeys": "1"} if experiment is None
                            else experiment)
        ch = writer.register_channel("/runs/r1/sensors", encoding, schema_id, channel_meta or {})
        data = block if isinstance(block, bytes) else SensorBlock(**block).SerializeToString()
        writer.add_message(ch, 0, data, 0)
        for rec in [record] if runs is None else runs:
            writer.add_metadata("momentid.run", rec)
        writer.finish()
    return path


def _raw(**kwargs):
    return lambda folder: read_recording(raw(folder, **kwargs))


_T4 = np.arange(4) * 0.01
_RUN = {"name": "r1", "index": "0", "added_mass": "[0.5]", "n_samples": "4", "complete": "true"}
#: Contradicting records: (id, raw() arguments, what the message must name).
_RAW = [
    ("format-version-9", dict(experiment={"format_version": "9"}), ("raw.mcap", "format_version", "'9'")),
    ("no-experiment-record", dict(experiment={}), ("raw.mcap", "format_version")),
    ("storeys-word", dict(experiment={"format_version": "2", "storeys": "two"}), ("raw.mcap", "storeys", "two")),
    ("structure-not-json", dict(experiment={"format_version": "2", "structure": "{oops"}), ("raw.mcap", "structure")),
    ("structure-wrong-keys", dict(experiment={"format_version": "2", "structure": '{"masses": 1}'}),
     ("raw.mcap", "structure")),
    ("scenario-a-list", dict(experiment={"format_version": "2", "scenario": "[1]"}), ("raw.mcap", "scenario")),
    ("statement-bad", dict(experiment={"format_version": "2", "statement": '{"storeys": "x"}'}),
     ("raw.mcap", "statement")),
    ("schema-name", dict(schema=("other.Block", "protobuf", SCHEMA_DATA)), ("raw.mcap", "other.Block")),
    ("schema-data-garbage", dict(schema=(SCHEMA_NAME, "protobuf", b"\xff\xff\xff")), ("raw.mcap", "schema")),
    ("message-encoding-json", dict(encoding="json"), ("raw.mcap", "json")),
    ("block-undecodable", dict(block=b"\xff\xff\xff\xff"), ("raw.mcap", "block 0", "undecodable")),
    ("block-time-nan", dict(block=dict(run="r1", n_samples=4, channels=("zdd", "a1"),
                                       time=[0, np.nan, 0.02, 0.03], values=np.zeros(8))),
     ("raw.mcap", "time[1]", "nan")),
    ("block-time-backwards", dict(block=dict(run="r1", n_samples=4, channels=("zdd", "a1"),
                                             time=[0, 0.02, 0.01, 0.03], values=np.zeros(8))), ("raw.mcap", "time[2]")),
    ("block-values-short", dict(block=dict(run="r1", n_samples=4, channels=("zdd", "a1"), time=_T4,
                                           values=np.zeros(7))), ("raw.mcap", "7 values")),
    ("block-other-run", dict(block=dict(run="r9", n_samples=4, channels=("zdd", "a1"), time=_T4,
                                        values=np.zeros(8))), ("raw.mcap", "'r9'")),
    ("units-in-g", dict(channel_meta={"channels": "zdd,a1", "units": "g,g"}), ("raw.mcap", "units", "g,g")),
    ("run-record-nameless", dict(runs=[{**_RUN, "name": ""}]), ("raw.mcap", "without a name")),
    ("run-record-twice", dict(runs=[_RUN, _RUN]), ("raw.mcap", "two", "'r1'")),
    ("added-mass-length", dict(runs=[{**_RUN, "added_mass": "[0.5, 0.5]"}]), ("raw.mcap", "added_mass")),
    ("added-mass-not-json", dict(runs=[{**_RUN, "added_mass": "half"}]), ("raw.mcap", "added_mass", "half")),
    ("n-samples-word", dict(runs=[{**_RUN, "n_samples": "four"}]), ("raw.mcap", "n_samples", "four")),
    ("index-word", dict(runs=[{**_RUN, "index": "first"}]), ("raw.mcap", "index", "first")),
    ("import-meta-bad", dict(channel_meta={"import": "[1]"}), ("raw.mcap", "import")),
]
#: Records that lose a run but keep another: recovery with a note.
_LOST = [
    ("run-never-completed", dict(runs=[]), ("raw.mcap", "no 'momentid.run' completion record")),
    ("run-short-of-samples", dict(runs=[{**_RUN, "n_samples": "6"}]), ("raw.mcap", "4 of its 6 samples")),
]


def _lost(kwargs):
    """A recording with a good run 'r0' written first, then the raw run 'r1' as ``kwargs`` make it."""
    return lambda folder: read_recording(_with_good_run(folder / "raw.mcap", kwargs))


def _with_good_run(path: Path, kwargs) -> Path:
    t = np.arange(4) * 0.01
    good_block = SensorBlock(run="r0", first_sample=0, n_samples=4, channels=("zdd", "a1"), time=t,
                             values=np.zeros(8)).SerializeToString()
    block = SensorBlock(run="r1", first_sample=0, n_samples=4, channels=("zdd", "a1"), time=t,
                        values=np.zeros(8)).SerializeToString()
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start()
        schema = writer.register_schema(SCHEMA_NAME, "protobuf", SCHEMA_DATA)
        writer.add_metadata("momentid.experiment", {"format_version": "2", "storeys": "1"})
        for name, data, recs in (("r0", good_block, [{**_RUN, "name": "r0"}]),
                                 ("r1", block, kwargs["runs"])):
            ch = writer.register_channel(f"/runs/{name}/sensors", "protobuf", schema, {})
            writer.add_message(ch, 0, data, 0)
            for rec in recs:
                writer.add_metadata("momentid.run", {**rec, "index": "0" if name == "r0" else "1"})
        writer.finish()
    return path


CASES = [Case(Group.RECORDING, id_, outcome, _read(mangle), names) for id_, outcome, mangle, names in _MANGLED] + [
    Case(Group.RECORDING, "writer-aborted", Outcome.RECOVERY, _aborted, ("rec.mcap", "aborted", "KeyboardInterrupt")),
    Case(Group.RECORDING, "missing-file", Outcome.ERROR, lambda f: read_recording(f / "none.mcap"), ("none.mcap",)),
    Case(Group.RECORDING, "a-folder", Outcome.ERROR, lambda f: read_recording(f), ("cannot open",)),
] + [Case(Group.RECORDING, id_, Outcome.ERROR, _raw(**kwargs), names) for id_, kwargs, names in _RAW] + [
    Case(Group.RECORDING, id_, Outcome.RECOVERY, _lost(kwargs), names) for id_, kwargs, names in _LOST]
