"""The recording format (``docs/recording-format.md``): record names and versions, the
``SensorBlock`` protobuf schema embedded in every file, its fast encoder, and the check of sample
times that the writer (:mod:`momentid.io.recording`) and the reader
(:mod:`momentid.io.recording_reader`) both apply."""

from __future__ import annotations

from collections.abc import Sequence
import re

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool
from google.protobuf.message_factory import GetMessageClass

from momentid.errors import RecordingError

__all__ = ["FORMAT_VERSION", "READABLE_VERSIONS", "IMPORT_META_KEYS", "SCHEMA_NAME", "EXPERIMENT_RECORD",
           "RUN_RECORD", "ABORTED_RECORD", "SENSOR_BLOCK_PROTO", "SENSOR_BLOCK_FIELDS", "SensorBlock",
           "SCHEMA_DATA", "run_topic", "RUN_TOPIC", "encode_block", "check_sample_times"]

#: Value of the ``format_version`` key momentid writes.  Version 2 added the
#: experiment's ``statement`` and a run channel's ``import`` metadata.
FORMAT_VERSION = "2"
#: Versions momentid reads (version 1 files have neither key).
READABLE_VERSIONS = ("1", "2")
#: ``run.meta`` keys of an imported run stored as the channel's ``import`` JSON.
IMPORT_META_KEYS = ("format", "source_file", "source_files", "sensors", "notes")
#: Full protobuf name of the sensor block message (the MCAP schema name).
SCHEMA_NAME = "momentid.SensorBlock"
#: Names of the metadata records: the experiment, a run's completion, an aborted writer.
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
SENSOR_BLOCK_FIELDS = (
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
    for name, number, type_, label in SENSOR_BLOCK_FIELDS:
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


#: The topic of a run's sensor blocks; group 1 is the run's name.
RUN_TOPIC = re.compile(r"^/runs/(.+)/sensors$")


def _varint(x: int) -> bytes:
    out = bytearray()
    while x > 0x7F:
        out.append((x & 0x7F) | 0x80)
        x >>= 7
    out.append(x)
    return bytes(out)


def encode_block(run: str, first: int, channels: Sequence[str], time: np.ndarray, values: np.ndarray) -> bytes:
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


def check_sample_times(t: np.ndarray, where: str) -> None:
    """Raise unless ``t`` (shape (n,), s) is finite and strictly increasing."""
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise RecordingError(f"{where}: time[{bad[0]}] = {float(t[bad[0]])!r}; expected finite sample times")
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        i = back[0]
        raise RecordingError(f"{where}: time[{i + 1}] = {float(t[i + 1])!r} follows {float(t[i])!r}; "
                             "expected strictly increasing times")
