"""No upload can exhaust the server: streamed to disk, limits checked as the bytes arrive and
before anything is unpacked or decoded, nothing left behind (issue 17)."""

from __future__ import annotations

import io
import struct
import zipfile
import zlib
from pathlib import Path

import pytest

from autotrack.errors import InputError
from autotrack_studio.config import AppConfig
from autotrack_studio.paths import UploadLimits, store_upload
from autotrack_studio.viser_private import (
    UploadPart,
    UploadStart,
    deliver_as_client,
    upload_button_id,
)
from tests.test_app import DEMO, RecordingChannel

PART = 512 * 1024
"""The browser's part size."""


def _rss() -> int:
    """This process's resident memory now (bytes)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS")


@pytest.fixture
def studio(tmp_path: Path):
    if not (DEMO / "img").is_dir():
        pytest.skip("static/demo is missing")
    from autotrack_studio.server import StudioServer

    leftover = tmp_path / "sessions" / ".incoming" / "123-killed.part"
    leftover.parent.mkdir(parents=True)
    leftover.write_bytes(b"x" * 1000)
    server = StudioServer(
        AppConfig(
            port=0,
            sessions_dir=tmp_path / "sessions",
            demo_dir=DEMO,
            tracker_threads=1,
            upload_limits=UploadLimits(max_upload_bytes=200 * 1024**2),
        )
    )
    yield server
    server.stop()


class Browser:
    """Sends upload messages as tab 1's browser would, through viser's message dispatch."""

    def __init__(self, studio) -> None:
        self.studio = studio
        self.channel = RecordingChannel()
        self.tab = studio.open_tab(self.channel, studio.viser.gui, studio.viser.scene, tab_id=1)
        assert self.tab.wait_idle()
        self.button = upload_button_id(self.tab.panels.sequence.upload)

    def send(self, message) -> None:
        deliver_as_client(self.studio.viser, 1, message)

    def start(self, name: str, size: int, transfer: str = "t1") -> None:
        self.send(UploadStart(self.button, transfer, name, "", -(-size // PART), size))

    def part(self, index: int, content: bytes, transfer: str = "t1") -> None:
        self.send(UploadPart(self.button, transfer, index, content))


def _incoming(studio) -> list[Path]:
    return sorted(studio.config.incoming_dir.iterdir())


def test_a_huge_declared_upload_is_refused_at_its_start_and_its_parts_dropped(studio) -> None:
    browser = Browser(studio)
    assert _incoming(studio) == []  # the killed server's leftover is gone
    before = _rss()
    browser.start("flight.mp4", 100 * 1024**3)  # 100 GB
    for index in range(400):  # 200 MB sent anyway, each part its own bytes
        browser.part(index, b"\x01" * PART)
    grown = _rss() - before
    assert grown < 60 * 1024**2, f"the server grew by {grown / 1e6:.0f} MB"
    assert "the limit is 210 MB" in browser.channel.notes[-1][0]
    assert _incoming(studio) == [] and studio.uploads.in_flight() == 0


def test_an_upload_arrives_on_disk_with_flat_memory_and_opens(studio) -> None:
    browser = Browser(studio)
    frames = sorted((DEMO / "img").iterdir())[:3]
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_STORED) as archive:
        for path in frames:
            archive.writestr(f"clip/{path.name}", path.read_bytes())
        archive.writestr("clip/padding.bin", bytes(150 * 1024**2))  # not an image: skipped
    content = buffer.getvalue()
    before = _rss()
    browser.start("clip.zip", len(content))
    for index, start in enumerate(range(0, len(content), PART)):
        browser.part(index, content[start : start + PART])
    grown = _rss() - before
    assert grown < 60 * 1024**2, f"the server grew by {grown / 1e6:.0f} MB over a 150 MB upload"
    assert browser.tab.wait_idle()
    assert browser.tab.controller.run.frame_count == 3
    assert _incoming(studio) == []  # the received zip was deleted once unpacked


@pytest.mark.parametrize(
    ("declared", "parts", "message"),
    [
        (PART + 10, [0, 1], "larger than it declared"),
        (2 * PART, [1], "out of order"),
        (2 * PART, [0, 0], "out of order"),
    ],
)
def test_a_lying_upload_is_ended_and_deleted(studio, declared, parts, message) -> None:
    browser = Browser(studio)
    browser.start("flight.mp4", declared)
    for index in parts:
        browser.part(index, bytes(PART))
    assert message in browser.channel.notes[-1][0]
    assert _incoming(studio) == [] and studio.uploads.in_flight() == 0


def test_an_abandoned_upload_is_deleted_when_its_tab_closes(studio) -> None:
    browser = Browser(studio)
    browser.start("flight.mp4", 10 * PART)
    browser.part(0, bytes(PART))
    assert len(_incoming(studio)) == 1
    studio.close_tab(1)
    assert _incoming(studio) == [] and studio.uploads.in_flight() == 0


def test_the_uploads_quota_and_one_upload_per_tab(studio, tmp_path: Path) -> None:
    browser = Browser(studio)
    browser.start("a.mp4", 10 * PART, transfer="a")
    browser.start("b.mp4", 10 * PART, transfer="b")
    assert "still arriving" in browser.channel.notes[-1][0]
    studio.uploads.limits = UploadLimits(max_upload_dir_bytes=15 * PART)
    studio.close_tab(1)
    browser = Browser(studio)
    (studio.config.upload_dir / "old.mp4").write_bytes(bytes(10 * PART))
    browser.start("c.mp4", 10 * PART, transfer="c")
    assert "quota" in browser.channel.notes[-1][0]


def _png_header(width: int, height: int) -> bytes:
    """A PNG whose header declares `width` x `height` (the pixel data is a stub)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", b"") + chunk(b"IEND", b"")


@pytest.mark.parametrize("size", [(20_000, 20_000), (8_000, 6_000)])
def test_a_zip_of_huge_pngs_is_refused_before_decoding(tmp_path: Path, size) -> None:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for index in range(50):
            archive.writestr(f"{index:03d}.png", _png_header(*size))
    uploads = tmp_path / "uploads"
    before = _rss()
    with pytest.raises(InputError, match="000.png (has more than|is 8000x6000 pixels)"):
        store_upload("bomb.zip", buffer.getvalue(), uploads, UploadLimits())
    assert _rss() - before < 50 * 1024**2
    assert list(uploads.iterdir()) == []  # the refused upload's folder is gone


def test_a_zip_whose_first_frame_is_1_gib_is_refused_before_writing(tmp_path: Path) -> None:
    bomb = tmp_path / "bomb.zip"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
        with archive.open("000001.png", "w", force_zip64=True) as member:
            zeros = bytes(64 * 1024**2)
            for _ in range(16):  # 1 GiB
                member.write(zeros)
        archive.writestr("000002.png", _png_header(64, 64))
    assert bomb.stat().st_size < 8 * 1024**2
    uploads = tmp_path / "uploads"
    before = _rss()
    with pytest.raises(InputError, match="000001.png is 1074 MB"):
        store_upload("bomb.zip", bomb, uploads, UploadLimits())
    assert _rss() - before < 50 * 1024**2
    assert list(uploads.iterdir()) == []
