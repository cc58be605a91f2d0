"""What a damaged or crafted session file cannot make the reader do: allocate what a chunk
declares (a 66 kB zstd bomb once cost 2.1 GB), take a frame index of 1e10 or -1 as real, or
end in an unexpected exception."""

from __future__ import annotations

import json
import struct
from dataclasses import replace
from typing import Any

import zstandard
from mcap.exceptions import McapError
from mcap.records import Chunk
from mcap.stream_reader import CRCValidationError, breakup_chunk

from autotrack.errors import SessionError

MAX_FRAME_INDEX = 100_000_000
"""Largest frame index a session may name (about five weeks of 30 fps video)."""
MAX_CHUNK_BYTES = 64 * 1024**2
"""Largest decompressed chunk a session may hold (the recorder writes one frame per chunk)."""
DECODE_ERRORS = (
    McapError,
    CRCValidationError,
    zstandard.ZstdError,
    struct.error,
    UnicodeDecodeError,
    json.JSONDecodeError,
    KeyError,
    TypeError,
    ValueError,
    RecursionError,
)
"""What a damaged or crafted file raises while it is decoded."""


def checked_frame_index(value: Any) -> int:
    """A recorded frame index, checked: a whole number in 0..MAX_FRAME_INDEX."""
    if isinstance(value, bool) or not isinstance(value, int | float) or value != int(value):
        raise SessionError(f"frame index {value!r} is not a whole number")
    if not 0 <= value <= MAX_FRAME_INDEX:
        raise SessionError(f"frame index {value!r} is out of range 0..{MAX_FRAME_INDEX}")
    return int(value)


def chunk_records(chunk: Chunk) -> list[Any]:
    """The records of a chunk, decompressed within `MAX_CHUNK_BYTES`.

    mcap's reader allocates whatever size a chunk (or its zstd frame) declares: a 66 kB file
    could make it allocate gigabytes. Here the declared size is checked first and the
    decompression stops at it, so a lying chunk costs at most `MAX_CHUNK_BYTES`.
    """
    size = chunk.uncompressed_size
    if size > MAX_CHUNK_BYTES:
        raise SessionError(
            f"a chunk declares {size / 1e6:.0f} MB uncompressed; sessions never hold chunks "
            f"over {MAX_CHUNK_BYTES / 1e6:.0f} MB"
        )
    if chunk.compression == "zstd":
        reader = zstandard.ZstdDecompressor().stream_reader(chunk.data, read_across_frames=True)
        pieces, received = [], 0
        while received <= size and (piece := reader.read(size + 1 - received)):
            pieces.append(piece)
            received += len(piece)
        data = b"".join(pieces)
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise SessionError(f"unsupported chunk compression {chunk.compression!r}")
    if len(data) != size:
        raise SessionError("a chunk does not decompress to the size it declares")
    return breakup_chunk(replace(chunk, compression="", data=data), validate_crc=True)
