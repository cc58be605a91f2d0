"""A server that runs for weeks for many users (issue 42): closed tabs freed, odd file names,
read-only and full disks, stalled uploads. Tabs are driven over real websockets
(tests/browser_socket.py), so viser's own connect and disconnect paths run."""

from __future__ import annotations

import collections
import contextlib
import errno
import gc
import io
import os
import shutil
import socket
import subprocess
import tempfile
import time
import tracemalloc
import weakref
import zipfile
from pathlib import Path

import numpy as np
import pytest

from autotrack.errors import InputError, SessionError
from autotrack_studio.browser_text import readable
from autotrack_studio.canvas import fit_letterbox, letterbox_image
from autotrack_studio.config import AppConfig
from autotrack_studio.owners import BrowserSpace, browser_tag
from autotrack_studio.paths import PARTIAL_PREFIX, UploadLimits, find_sequences, store_upload
from autotrack_studio.viser_private import (
    UploadPart,
    UploadStart,
    deliver_as_client,
    upload_button_id,
)
from tests.browser_socket import SocketBrowser
from tests.test_app import DEMO, _draw_demo_boxes, _open_tab

ROOT = "root"
"""The --allow-root folder made under each test's tmp_path."""


@pytest.fixture
def studio(tmp_path: Path):
    if not (DEMO / "img").is_dir():
        pytest.skip("static/demo is missing")
    from autotrack_studio.server import StudioServer

    (tmp_path / ROOT).mkdir()
    server = StudioServer(
        AppConfig(
            port=0,
            sessions_dir=tmp_path / "sessions",
            allowed_roots=(tmp_path / ROOT,),
            demo_dir=DEMO,
            tracker_threads=1,
            token="secret-token",
        )
    )
    server.warm_up.join()
    yield server
    server.stop()


def _wait(predicate, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "condition not reached"
        time.sleep(0.05)


def open_socket_tab(studio, **options):  # noqa: ANN001, ANN003, ANN201
    """A tab opened over a websocket: (the browser, the server's Tab for it)."""
    known = set(studio.tabs)
    browser = SocketBrowser(studio.port, token=studio.config.token, **options)
    _wait(lambda: set(studio.tabs) - known)
    (tab_id,) = set(studio.tabs) - known
    tab = studio.tabs[tab_id]
    assert tab.wait_idle()
    return browser, tab


def _live(references: list[weakref.ref]) -> int:
    gc.collect()
    return sum(reference() is not None for reference in references)


def test_closed_tabs_are_freed_with_their_controller_and_results(studio) -> None:
    """Each tab opens the demo, tracks four targets a few frames and is closed; afterwards no
    Tab, controller or run of them is alive (issue 42 item 1: the upload receiver kept each
    client's connection, which held the tab through its scene callbacks)."""
    references: list[weakref.ref] = []
    for _ in range(3):
        browser, tab = open_socket_tab(studio)
        _draw_demo_boxes(tab)
        tab.worker.submit(tab.seek, 4)
        assert tab.wait_idle()
        assert tab.controller.cursor == 4 and tab.controller.run.targets
        references += [weakref.ref(tab), weakref.ref(tab.controller)]
        references.append(weakref.ref(tab.controller.run))
        del tab
        browser.close()
        _wait(lambda: not studio.tabs)
    _wait(lambda: _live(references) == 0)


def _frames_folder(folder: Path, count: int, odd_frame: int | None = None) -> Path:
    """A folder of the demo's first `count` frames; frame `odd_frame` (0-based) gets a name
    whose bytes are not UTF-8."""
    (folder / "img").mkdir(parents=True)
    for index, frame in enumerate(sorted((DEMO / "img").iterdir())[:count]):
        name = frame.name if index != odd_frame else os.fsdecode(b"0000\xe9" + frame.name.encode())
        shutil.copy(frame, folder / "img" / name)
    return folder


def _status_sent(browser: SocketBrowser, text: str) -> bool:
    """Whether a markdown update holding `text` reached the browser."""
    return any(
        text in str(message["updates"].get("_markdown", ""))
        for message in browser.messages("GuiUpdateMessage")
    )


def test_a_folder_and_a_frame_named_in_latin_1_leave_every_tab_working(studio) -> None:
    """Issue 42 item 2: a folder whose name is not UTF-8 under --allow-root closed every new
    tab's websocket (1011); a frame file so named dropped the tab when played."""
    root = studio.config.allowed_roots[0]
    _frames_folder(Path(os.fsdecode(os.fsencode(root) + b"/caf\xe9")), 4)
    _frames_folder(root / "plain", 6, odd_frame=3)
    browser, tab = open_socket_tab(studio)
    shown = f"{ROOT}/caf\\xe9"
    assert shown in tab.panels.sequence.dropdown.options
    tab.worker.submit(tab.controller.open_listed, shown)
    assert tab.wait_idle()
    assert tab.controller.run.frame_count == 4
    assert tab.panels.sequence.path.value == shown
    tab.worker.submit(tab.controller.open_typed, shown)  # the escaped spelling, typed back
    assert tab.wait_idle() and tab.controller.run.frame_count == 4
    browser.wait_for(lambda: _status_sent(browser, "caf\\\\xe9"))  # as markdown escapes it
    tab.worker.submit(tab.controller.open_typed, f"{ROOT}/plain")
    assert tab.wait_idle() and tab.controller.run.frame_count == 6
    tab.worker.submit(tab.seek, 5)  # past the oddly named frame
    assert tab.wait_idle() and tab.controller.cursor == 5
    browser.wait_for(lambda: _status_sent(browser, "frame 6 / 6"))
    assert browser.connection.close_code is None  # still connected
    browser.close()
    second, _ = open_socket_tab(studio)  # a new tab connects and stays
    second.wait_for(lambda: _status_sent(second, "Opened"))
    assert second.connection.close_code is None
    second.close()


def test_typed_html_shows_as_text_and_a_huge_path_is_not_echoed_whole(studio) -> None:
    """Issue 42 item 10: a typed path was echoed into the status line as raw HTML (an external
    image fetched, a style applied), and a 1 MB path was echoed back whole."""
    browser, tab = open_socket_tab(studio)
    typed = (
        "<img src=http://127.0.0.1:9/x.png><style>*{color:red}</style>![x](http://127.0.0.1:9/y)"
    )
    tab.worker.submit(tab.controller.open_typed, typed)
    assert tab.wait_idle()
    _wait(lambda: "no such file" in tab.panels.status.content)
    status = tab.panels.status.content
    assert "&lt;img src=http://127.0.0.1:9/x.png&gt;&lt;style&gt;" in status
    assert "<" not in status and "![" not in status and "\\!\\[x\\]" in status
    tab.worker.submit(tab.controller.open_typed, "a" * 1_000_000)
    assert tab.wait_idle()
    _wait(lambda: "aaaa" in tab.panels.status.content)
    assert len(tab.panels.status.content) < 1000
    assert browser.connection.close_code is None
    browser.close()


@contextlib.contextmanager
def read_only(folder: Path):
    """`folder` made read-only for this process (root ignores permissions: immutable then)."""
    if os.geteuid() == 0:
        if shutil.which("chattr") is None:
            pytest.skip("running as root without chattr: cannot make a folder read-only")
        subprocess.run(["chattr", "+i", str(folder)], check=True)
        try:
            yield
        finally:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
    else:
        folder.chmod(0o555)
        try:
            yield
        finally:
            folder.chmod(0o755)


def test_a_read_only_sessions_folder_is_refused_before_the_run_is_closed(studio) -> None:
    """Issue 42 item 4: reopening with a read-only sessions folder ended in a traceback with
    the tab half-closed; now one line, and the open run with its targets stays."""
    tab, channel = _open_tab(studio)
    for command, *args in ((tab.controller.load_boxes_json,), (tab.seek, 3)):
        tab.worker.submit(command, *args)
        assert tab.wait_idle()  # one at a time: a waiting command interrupts tracking ahead
    tab.worker.submit(tab.controller.sessions.refresh)
    assert tab.wait_idle()
    run = tab.controller.run
    assert len(run.targets) == 4 and run.tracked_until == 3
    (listed,) = tab.controller.sessions.choices
    with read_only(tab.controller.space.sessions_dir):
        tab.worker.submit(tab.controller.sessions.reopen, listed)
        assert tab.wait_idle()
    message, error = channel.notes[-1]
    assert error and message.startswith("cannot write to the sessions folder sessions/browser-")
    assert "\n" not in message and "Error" not in message
    assert tab.controller.run is run and len(run.targets) == 4 and run.tracked_until == 3
    tab.worker.submit(tab.seek, 5)  # still tracking, still recording
    assert tab.wait_idle() and run.tracked_until == 5 and run.session_path.is_file()


def test_a_tab_closed_on_a_full_disk_releases_its_recording(studio, monkeypatch) -> None:
    """Issue 42 item 3: closing a tab on a full disk raised in close_tab before the registry
    let the file go, which stayed 'being recorded by another tab' until restart."""
    tab, _ = _open_tab(studio)
    tab.worker.submit(tab.controller.load_boxes_json)
    assert tab.wait_idle()
    run = tab.controller.run
    path = run.session_path
    assert studio.recordings.writer_of(path) == tab.tab_id

    def disk_full() -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(run, "close", disk_full)
    studio.close_tab(tab.tab_id)
    assert studio.recordings.writer_of(path) is None
    other, channel = _open_tab(studio, tab_id=2)
    other.worker.submit(other.controller.sessions.refresh)
    assert other.wait_idle()
    other.worker.submit(other.controller.sessions.reopen, readable(path.name))
    assert other.wait_idle()
    assert not any("another tab" in note for note, _ in channel.notes)
    assert other.controller.message.startswith(f"Reopened {path.name}")


def test_downloads_work_while_the_disk_is_full(studio, monkeypatch, tmp_path: Path) -> None:
    """Issue 42 item 3: while the disk was full, "Download tracks" failed with the session's
    error (the flush) and its scratch files; it now sends what the session file holds."""
    tab, channel = _open_tab(studio)
    tab.worker.submit(tab.controller.load_boxes_json)
    assert tab.wait_idle()
    tab.worker.submit(tab.seek, 3)
    assert tab.wait_idle()
    run = tab.controller.run
    run.flush()

    def disk_full() -> None:
        raise SessionError("cannot write the session file: [Errno 28] No space left on device")

    monkeypatch.setattr(run, "flush", disk_full)
    full = tmp_path / "full-temp"
    full.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(full))
    with read_only(full):
        for what in ("tracks", "poses"):
            tab.worker.submit(tab.download, what)
            assert tab.wait_idle()
    (tracks_name, tracks), (poses_name, _) = channel.downloads[-2:]
    assert tracks_name.endswith("_tracks.zip") and poses_name.endswith("_poses.tum")
    with zipfile.ZipFile(io.BytesIO(tracks)) as archive:
        (track_file,) = [name for name in archive.namelist() if name.startswith("T1")]
        lines = archive.read(track_file).decode().splitlines()
    assert len(lines) == 4 and "nan" not in lines[3].lower()


def test_a_canvas_of_extreme_aspect_costs_no_more_than_its_output() -> None:
    """Issue 42 item 5: the letterbox allocated the padded frame at full resolution before
    scaling it down; a 1x1500 canvas made a 960 x 1.44M-pixel frame (about 4 GB)."""
    frame = np.full((540, 960, 3), 200, dtype=np.uint8)
    for canvas in ((1, 1500), (1500, 1), (1000, 700)):
        letterbox = fit_letterbox((960, 540), canvas)
        tracemalloc.start()
        try:
            image = letterbox_image(frame, letterbox, 1000)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 8 * 1024**2, f"{canvas}: {peak / 1e6:.0f} MB"
        assert max(image.shape[:2]) <= 1000 and image.dtype == np.uint8
        aspect = letterbox.padded_width / letterbox.padded_height
        assert abs(image.shape[1] / image.shape[0] - aspect) <= aspect * 0.5 + 1 / image.shape[0]
    assert image.shape[:2] == (672, 960) and image[336, 480].tolist() == [200, 200, 200]


def test_a_camera_message_of_no_size_leaves_the_tab_drawing(studio) -> None:
    """Issue 42 item 10: width/height 0 or negative camera messages raised in the canvas code;
    the canvas is then drawn at the default size."""
    for canvas in ((0, 600), (800, -5)):
        browser, tab = open_socket_tab(studio, canvas=canvas)
        assert tab.channel.canvas_size() is None
        browser.wait_for(lambda b=browser: bool(b.messages("BackgroundImageMessage")))
        assert browser.connection.close_code is None
        browser.close()


# -- uploads (issue 42 items 6-8) -----------------------------------------------------------------

PART = 512 * 1024
DiskUsage = collections.namedtuple("DiskUsage", "total used free")
"""What shutil.disk_usage answers."""


class _UploadingTab:
    """A tab on the server's GUI whose upload messages arrive as from client `tab_id`."""

    def __init__(self, studio, tab_id: int, browser: str) -> None:  # noqa: ANN001
        self.studio, self.tab_id = studio, tab_id
        self.tab, self.channel = _open_tab(studio, tab_id=tab_id, browser=browser)
        self.button = upload_button_id(self.tab.panels.sequence.upload)

    def start(self, transfer: str, parts: int) -> None:
        message = UploadStart(self.button, transfer, f"{transfer}.mp4", "", parts, parts * PART)
        deliver_as_client(self.studio.viser, self.tab_id, message)

    def part(self, transfer: str, index: int) -> None:
        message = UploadPart(self.button, transfer, index, bytes(PART))
        deliver_as_client(self.studio.viser, self.tab_id, message)

    def last_note(self) -> str:
        return self.channel.notes[-1][0] if self.channel.notes else ""


def test_a_stalled_upload_is_ended_and_one_browser_has_one_upload_in_flight(studio) -> None:
    """Issue 42 item 6: uploads that sent one part and then nothing held the quota for as long
    as their tabs stayed open, locking every other browser out."""
    now = [1000.0]
    studio.uploads.clock = lambda: now[0]
    studio.uploads.limits = UploadLimits(max_upload_dir_bytes=15 * PART, idle_seconds=60.0)
    stalling = _UploadingTab(studio, 1, "mallory")
    same_browser = _UploadingTab(studio, 2, "mallory")
    other = _UploadingTab(studio, 3, "alice")
    stalling.start("stalled", 10)
    stalling.part("stalled", 0)
    same_browser.start("second", 2)
    assert "an upload from this browser is still arriving" in same_browser.last_note()
    now[0] += 30.0
    other.start("wanted", 10)
    assert "quota" in other.last_note()  # still arriving, as far as anyone can tell
    now[0] += 31.0  # 61 s without a part
    other.start("wanted", 10)
    assert "stopped arriving" in stalling.last_note()
    assert studio.uploads.in_flight() == 1
    for index in range(10):
        other.part("wanted", index)
        now[0] += 59.0  # slow but steady: never idle for 60 s
    assert studio.uploads.in_flight() == 0
    assert other.tab.wait_idle()
    assert not any("stopped arriving" in note for note, _ in other.channel.notes)


def test_a_half_stored_upload_is_hidden_and_removed_at_the_next_start(tmp_path: Path) -> None:
    """Issue 42 item 7: a server killed while unpacking left a partial upload that counted
    against the quota, was listed to its owner and opened as a shorter sequence."""
    from autotrack_studio.server import StudioServer

    config = AppConfig(port=0, sessions_dir=tmp_path / "sessions", demo_dir=DEMO, token="t")
    browser_uploads = config.upload_dir / "browser-0123456789abcdef"
    stored = store_upload("clip.zip", _zip_of_frames(3), browser_uploads, UploadLimits())
    assert not stored.name.startswith(PARTIAL_PREFIX) and len(list(stored.glob("img/*"))) == 3
    killed = browser_uploads / f"{PARTIAL_PREFIX}20261202-000000_clip_abcdef"
    shutil.copytree(stored, killed)  # what a kill -9 mid-unpack leaves
    assert find_sequences((browser_uploads,)) == [stored]  # never listed
    server = StudioServer(config)
    try:
        assert not killed.exists() and stored.is_dir()
    finally:
        server.stop()


def _zip_of_frames(count: int, size: int = 0) -> bytes:
    """A zip of `count` demo frames, each padded by `size` bytes of zeros (still a JPEG)."""
    frames = sorted((DEMO / "img").iterdir())
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for index in range(count):
            archive.writestr(f"{index:04d}.jpg", frames[index].read_bytes() + bytes(size))
    return buffer.getvalue()


def test_unpacking_stops_at_the_free_space_reserve(tmp_path: Path, monkeypatch) -> None:
    """Issue 42 item 8: the 256 MB reserve was checked only when an upload started; a small zip
    of large uniform images drove free space to 3 MB and ended in "internal error: OSError"."""
    uploads = tmp_path / "uploads"
    disk = 400 * 1024**2  # the disk as this test sees it: 400 MB free before the upload

    def usage(path) -> DiskUsage:  # noqa: ANN001
        used = sum(f.stat().st_size for f in uploads.rglob("*") if f.is_file())
        return DiskUsage(disk, used, disk - used)

    monkeypatch.setattr(shutil, "disk_usage", usage)
    content = _zip_of_frames(20, size=4 * 1024**2)  # 20 x 4 MB unpacked, well within limits
    assert len(content) < 2 * 1024**2
    with pytest.raises(InputError, match="^the server's disk is nearly full: the zip was not"):
        store_upload("big.zip", content, uploads, UploadLimits(free_space_reserve=360 * 1024**2))
    assert list(uploads.iterdir()) == []
    stored = store_upload("big.zip", content, uploads, UploadLimits())  # 256 MB: it fits
    assert len(list(stored.glob("img/*"))) == 20


def _status_of(port: int, request_lines: list[str]) -> int:
    """The HTTP status the server answers a raw request with (headers sent as given)."""
    with socket.create_connection(("127.0.0.1", port), timeout=30) as connection:
        connection.sendall(("\r\n".join(request_lines) + "\r\n\r\n").encode("utf-8"))
        answer = b""
        while b"\r\n" not in answer:
            chunk = connection.recv(4096)
            if not chunk:
                break
            answer += chunk
    return int(answer.split(b" ", 2)[1])


@pytest.mark.parametrize(
    "lines",
    [
        ["GET /?token=%C3%A9t%C3%A9 HTTP/1.1", "Host: 127.0.0.1"],  # a non-ASCII token
        ["GET / HTTP/1.1", "Host: 127.0.0.1", "Cookie: autotrack_token_PORT=été"],
        ["GET /?token=secret-token HTTP/1.1", "Host: 127.0.0.1", "Host: evil.example"],
        [
            "GET /?token=secret-token HTTP/1.1",
            "Host: 127.0.0.1:PORT",
            "Origin: http://127.0.0.1:PORT",
            "Origin: http://evil.example",
        ],
        ["GET /?token=secret-token HTTP/1.1", "Host: [::1"],  # no host a URL can hold
    ],
)
def test_every_malformed_token_or_header_gets_403(studio, lines) -> None:
    """Issue 42 item 10: a non-ASCII token or duplicate Host/Origin headers gave HTTP 500."""
    port = studio.port
    assert _status_of(port, ["GET /?token=secret-token HTTP/1.1", "Host: 127.0.0.1"]) == 200
    assert _status_of(port, [line.replace("PORT", str(port)) for line in lines]) == 403


def test_another_browsers_upload_is_refused_like_a_missing_path(tmp_path: Path) -> None:
    """Issue 42 item 10: a path in another browser's space got a different refusal text than a
    missing one (telling that it exists)."""
    from autotrack_studio.server import StudioServer

    sessions = tmp_path / "sessions"
    config = AppConfig(
        port=0, sessions_dir=sessions, allowed_roots=(sessions,), demo_dir=DEMO, token="t"
    )
    server = StudioServer(config)
    try:
        alices = _frames_folder(config.upload_dir / f"browser-{browser_tag('alice')}" / "clip", 2)
        tab, channel = _open_tab(server, browser="bob")
        refusals = []
        for typed in (alices, alices.with_name("nothing-here")):
            tab.worker.submit(tab.controller.open_typed, str(typed))
            assert tab.wait_idle()
            refusals.append(channel.notes[-1][0].replace(typed.name, "NAME"))
        assert refusals[0] == refusals[1]
        assert "no such file or folder among those this server may open" in refusals[0]
    finally:
        server.stop()


def test_a_jpeg_given_as_the_scene_file_gets_a_clear_message(studio) -> None:
    """Issue 42 item 10: a JPEG as the scene file gave "internal error"."""
    tab, channel = _open_tab(studio)
    tab.worker.submit(tab.controller.use_scene, "demo/img/00001.jpg")
    assert tab.wait_idle()
    message, error = channel.notes[-1]
    assert error and message == "scene file demo/img/00001.jpg is not a JSON text file"
    assert tab.controller.run is not None and tab.controller.run.scene is not None  # kept


def test_a_tab_opens_while_another_tab_of_its_browser_removes_its_empty_upload_folder(
    studio,
) -> None:
    """A reloaded page: the closing tab's browser space removes its empty upload folder
    (BrowserSpace.release) while the new tab of the same browser lists its roots; a folder gone
    by then left the new tab unopened ("allowed root ... is not an existing folder")."""

    class FolderRemovedOnceSeen(type(Path())):
        def is_dir(self) -> bool:
            present = super().is_dir()
            self.rmdir()  # the other tab's release, right after this tab saw the folder
            return present

    folder = studio.config.upload_dir / "browser-closing"
    folder.mkdir(parents=True)
    roots = studio.config.browsable_roots((FolderRemovedOnceSeen(folder),))
    assert roots[: len(studio.config.allowed_roots)] == tuple(
        root.resolve() for root in studio.config.allowed_roots
    )
    assert not folder.exists()  # gone, and the tab's roots were made all the same
    with pytest.raises(InputError, match="is not an existing folder"):
        AppConfig(allowed_roots=(studio.config.upload_dir / "no-such-root",)).browsable_roots()


def test_an_upload_folder_removed_while_a_tab_makes_it_is_made_again(
    tmp_path: Path, monkeypatch
) -> None:
    """The other side of that race: the closing tab removes the folder after the new tab's
    mkdir found it and before mkdir checked it is a folder, so mkdir reported it existing
    and not a folder (FileExistsError in a CI run); the new tab makes it again."""
    space = BrowserSpace(tmp_path / "sessions", tmp_path / "uploads", "racing")
    space.upload_dir.mkdir(parents=True)
    real_mkdir = Path.mkdir
    raced = []

    def mkdir_racing_a_release(self, *args, **kwargs):
        if self == space.upload_dir and not raced:
            raced.append(self)
            self.rmdir()  # the other tab's release
            raise FileExistsError(errno.EEXIST, "File exists", str(self))
        return real_mkdir(self, *args, **kwargs)

    monkeypatch.setattr(Path, "mkdir", mkdir_racing_a_release)
    assert space.upload_roots() == (space.upload_dir,)
    assert raced and space.upload_dir.is_dir()
    monkeypatch.setattr(Path, "mkdir", real_mkdir)
    # A file where the folder should be is still refused.
    space.upload_dir.rmdir()
    space.upload_dir.write_text("not a folder")
    with pytest.raises(FileExistsError):
        space.upload_roots()
