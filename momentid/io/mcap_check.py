"""Damage checks of an MCAP file beyond what the stock stream reader does.

The stream reader of the ``mcap`` package trusts length fields inside a record and never looks at
the summary section; a recording read by :func:`momentid.io.recording.read_recording` is checked
here for both, so that damage is reported (a note) instead of crashing or passing silently.
"""

from __future__ import annotations

import io
import struct
from typing import BinaryIO
import zlib

from mcap.exceptions import McapError
from mcap.records import AttachmentIndex, ChunkIndex, MetadataIndex
from mcap.stream_reader import StreamReader

__all__ = ["DAMAGE", "MCAP_MAGIC", "Bounded", "summary_damage"]

MCAP_MAGIC = b"\x89MCAP0\r\n"
#: What the stock reader raises on a damaged file.
DAMAGE = (McapError, struct.error, ValueError, EOFError, RuntimeError, OverflowError)
try:  # chunks compressed by other writers
    import zstandard
    DAMAGE += (zstandard.ZstdError,)
except ImportError:  # pragma: no cover
    pass


class Bounded:
    """A read-only view of an open file that never asks for more bytes than the file has left: a
    damaged length field inside a record (a chunk's data length of 2**57, say) then reads short
    and fails as damage instead of making the stock reader allocate that many bytes.  (Not an
    ``io.RawIOBase``: the stock reader would wrap that in a BufferedReader, which reads around it.)"""

    def __init__(self, f: BinaryIO, size: int):
        self._f, self._size = f, size

    def read(self, n: int | None = -1) -> bytes:
        """At most ``n`` bytes (all when ``n`` is None or negative), never past the file's ``size``."""
        left = max(self._size - self._f.tell(), 0)
        return self._f.read(left if n is None or n < 0 else min(n, left))

    def tell(self) -> int:
        """The position in the file (bytes)."""
        return self._f.tell()


#: The footer record (opcode, length, summary_start, summary_offset_start, summary_crc) and the
#: closing magic: the last bytes of a complete MCAP file.
_FOOTER = struct.Struct("<BQQQI")
_OPCODE_FOOTER, _OPCODE_CHUNK, _OPCODE_METADATA, _OPCODE_ATTACHMENT = 0x02, 0x06, 0x0C, 0x09


def summary_damage(f: BinaryIO, size: int) -> str | None:
    """What is wrong with the summary section and footer of the open file ``f`` (or None).

    The streaming read never needs them, but other MCAP tools jump through their indexes, so
    damage there is reported: a summary CRC mismatch, or an index that points at the wrong record.
    """
    footer_at = size - _FOOTER.size - len(MCAP_MAGIC)
    if footer_at < len(MCAP_MAGIC):
        return "no footer"
    f.seek(footer_at)
    tail = f.read(_FOOTER.size + len(MCAP_MAGIC))
    opcode, length, summary_start, _, crc = _FOOTER.unpack(tail[:_FOOTER.size])
    if opcode != _OPCODE_FOOTER or length != _FOOTER.size - 9 or tail[_FOOTER.size:] != MCAP_MAGIC:
        return f"the last {len(tail)} bytes are not a footer and the MCAP magic"
    if summary_start == 0:
        return None  # a file without a summary section: allowed by the format
    if not len(MCAP_MAGIC) <= summary_start <= footer_at:
        return f"footer summary_start = {summary_start}, outside the file"
    f.seek(summary_start)
    summary = f.read(footer_at - summary_start)
    if crc != 0 and zlib.crc32(summary + tail[:_FOOTER.size - 4]) != crc:
        return f"summary CRC mismatch (footer says {crc:#010x})"
    try:
        for record in StreamReader(io.BytesIO(summary + tail), skip_magic=True,
                                   record_size_limit=len(summary) + len(tail)).records:
            if isinstance(record, ChunkIndex):
                where, want = record.chunk_start_offset, _OPCODE_CHUNK
            elif isinstance(record, MetadataIndex):
                where, want = record.offset, _OPCODE_METADATA
            elif isinstance(record, AttachmentIndex):
                where, want = record.offset, _OPCODE_ATTACHMENT
            else:
                continue
            f.seek(where)
            if where >= summary_start or f.read(1) != bytes([want]):
                return f"{type(record).__name__} points at byte {where}, which holds no such record"
    except DAMAGE as e:
        return f"{type(e).__name__}: {e}"
    return None
