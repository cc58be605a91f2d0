"""The records of an MCAP file read in file order, also from a file cut short by a crash.

`scan_records` finds where the complete records end (a record whose length runs past the end of
the file is where it was cut); `iter_records` decodes the records before that point, chunks
unpacked (within `limits`). The reader, the embedded frames and the finished copy of a session
still being recorded all read a file through these two.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator
from typing import Any, BinaryIO

from mcap.exceptions import EndOfFile
from mcap.records import Chunk, DataEnd
from mcap.stream_reader import StreamReader

from autotrack.errors import SessionError
from autotrack.sessions.limits import chunk_records

MCAP_MAGIC = b"\x89MCAP0\r\n"
"""The first (and last) bytes of every MCAP file."""
_OPCODE_FOOTER = 0x02
_OPCODE_DATA_END = 0x0F
_KNOWN_OPCODES = frozenset(range(0x01, 0x10))


class _PrefixReader(io.RawIOBase):
    """Read-only view of the first `limit` bytes of a binary file."""

    def __init__(self, handle: BinaryIO, limit: int) -> None:
        self._handle = handle
        self._remaining = limit

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        view = memoryview(buffer)
        wanted = min(len(view), self._remaining)
        if wanted <= 0:
            return 0
        data = self._handle.read(wanted)
        view[: len(data)] = data
        self._remaining -= len(data)
        return len(data)


def scan_records(handle: BinaryIO, size: int, name: str) -> tuple[int, bool]:
    """Walk the top-level records of the `size`-byte file `handle` (`name` for messages):
    (end of the last complete data-section record, whether the file is complete).

    Raises SessionError for a file that is not MCAP or names an unknown record type.
    """
    handle.seek(0)
    if handle.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
        raise SessionError(f"{name} is not an MCAP file (it does not start with the MCAP magic)")
    offset = len(MCAP_MAGIC)
    data_end = offset
    in_data_section = True
    while size - offset >= 9:
        handle.seek(offset)
        opcode, length = struct.unpack("<BQ", handle.read(9))
        if opcode not in _KNOWN_OPCODES and opcode < 0x80:
            raise SessionError(
                f"{name} is corrupted: unknown record type 0x{opcode:02x} at byte {offset}"
            )
        end = offset + 9 + length
        if end > size:
            break
        if opcode == _OPCODE_FOOTER:
            handle.seek(end)
            return data_end, handle.read(len(MCAP_MAGIC)) == MCAP_MAGIC
        if in_data_section:
            data_end = end
        if opcode == _OPCODE_DATA_END:
            in_data_section = False
        offset = end
    return data_end, False


def iter_records(handle: BinaryIO, limit: int) -> Iterator[Any]:
    """The records of the file's first `limit` bytes (from `scan_records`), in file order, each
    chunk's records in place of the chunk; CRCs checked. Decoding errors are those of
    `limits.DECODE_ERRORS`."""
    handle.seek(0)
    reader = StreamReader(_PrefixReader(handle, limit), validate_crcs=True, emit_chunks=True)
    records = reader.records
    while True:
        try:
            record = next(records)
        except (StopIteration, EndOfFile):
            return
        if isinstance(record, Chunk):
            yield from chunk_records(record)
        else:
            yield record
        if isinstance(record, DataEnd):
            return
