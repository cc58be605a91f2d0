"""A decompression bomb in a session file is refused within bounded memory (issue 17)."""

from __future__ import annotations

from pathlib import Path

import pytest
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.records import Chunk, DataEnd, Header

from autotrack.cli import main
from autotrack.errors import SessionError
from autotrack.sessions import open_session

MAGIC = b"\x89MCAP0\r\n"


def _rss() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS")


def _zstd_of_zeros(size: int) -> bytes:
    """A zstd frame of `size` zero bytes (its header declares the size), built in pieces."""
    compressor = zstandard.ZstdCompressor(level=1).compressobj(size=size)
    piece = bytes(64 * 1024**2)
    parts = [compressor.compress(piece) for _ in range(size // len(piece))]
    return b"".join([*parts, compressor.flush()])


def _bomb(path: Path, data: bytes, declared: int) -> Path:
    builder = RecordBuilder()
    Header(profile="", library="bomb").write(builder)
    Chunk(
        compression="zstd",
        data=data,
        message_start_time=0,
        message_end_time=0,
        uncompressed_crc=0,
        uncompressed_size=declared,
    ).write(builder)
    DataEnd(data_section_crc=0).write(builder)
    path.write_bytes(MAGIC + builder.end())
    return path


@pytest.fixture(scope="module")
def two_gib_of_zeros() -> bytes:
    data = _zstd_of_zeros(2 * 1024**3)
    assert len(data) < 200_000  # the bomb was 66 kB
    return data


@pytest.mark.parametrize(
    ("declared", "message"),
    [
        (2 * 1024**3, "a chunk declares 2147 MB uncompressed"),  # the chunk says it
        (1000, "does not decompress to the size it declares"),  # only the zstd frame says it
    ],
)
def test_a_zstd_bomb_session_is_refused_in_bounded_memory(
    tmp_path: Path, two_gib_of_zeros: bytes, declared: int, message: str, capsys
) -> None:
    bomb = _bomb(tmp_path / "bomb.mcap", two_gib_of_zeros, declared)
    before = _rss()
    with pytest.raises(SessionError, match=message):
        open_session(bomb)
    assert main(["session", "info", str(bomb)]) == 2
    grown = _rss() - before
    assert grown < 100 * 1024**2, f"reading the bomb grew the process by {grown / 1e6:.0f} MB"
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "Traceback" not in err
