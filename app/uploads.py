"""Uploads received straight to disk, with every limit enforced while the bytes arrive.

viser's upload button keeps every part of a transfer in memory and joins them at the end, for a
size the client only declares: a client declaring 100 GB grows the server without bound, and a
file over the limit is refused only after all of it arrived. `UploadReceiver` takes over the two
upload messages of a tab's GUI (`FileTransferStartUpload`, `FileTransferPart`): a transfer is
refused at its start when its declared size, its type, the uploads quota or the free disk space
say no; its parts are appended to a file under `incoming/` in order, and a part out of order or
beyond the declared size ends it. Memory per transfer is one 512 kB part. A refused, broken or
abandoned (tab closed) transfer's file is deleted at once, a stalled one (nothing for
`UploadLimits.idle_seconds`) when the next transfer starts, and leftovers of a killed server
when the next one starts. One browser has one transfer in flight. viser's messages are
reached through app/viser_private.py; a GUI's websocket is let go when its last tab closes.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import viser

from autotrack_studio.paths import (
    VIDEO_SUFFIXES,
    UploadLimits,
    folder_bytes,
    remove_partial_uploads,
    safe_file_name,
)
from autotrack_studio.viser_private import (
    UploadHandlers,
    UploadPart,
    UploadStart,
    acknowledge_upload,
    take_over_uploads,
    upload_button_id,
)


@dataclass
class _Transfer:
    """One upload in progress."""

    tab_id: int
    browser: str | None
    button: str
    name: str
    declared: int
    part_count: int
    path: Path
    sink: BinaryIO
    last_seen: float
    """When its last message arrived (the receiver's clock)."""
    received: int = 0
    next_part: int = 0


STALLED = "the upload stopped arriving and was ended; upload the file again"
"""Told to a tab whose upload sent nothing for `UploadLimits.idle_seconds`."""


@dataclass
class _Interface:
    """Our upload handlers on one GUI's websocket, and the tabs whose buttons use it."""

    handlers: UploadHandlers
    tab_ids: set[int] = field(default_factory=set)


@dataclass(frozen=True)
class _Button:
    """An upload button taken over: its tab, where finished files go, where refusals go."""

    tab_id: int
    deliver: Callable[[str, Path], None]
    refuse: Callable[[str], None]
    browser: str | None = None
    """The browser of its tab (None: a space of its own)."""


class UploadReceiver:
    """Receives the uploads of every tab's upload button into `incoming`."""

    def __init__(
        self,
        incoming: Path,
        upload_dir: Path,
        limits: UploadLimits,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.incoming = incoming
        self.upload_dir = upload_dir
        self.limits = limits
        self.clock = clock
        """Seconds, for the idle timeout (time.monotonic; tests pass their own)."""
        self._lock = threading.Lock()
        self._buttons: dict[str, _Button] = {}
        self._transfers: dict[str, _Transfer] = {}
        self._interfaces: dict[int, _Interface] = {}
        """The GUIs whose uploads we receive, by id (a client's, or the server's in tests)."""
        shutil.rmtree(incoming, ignore_errors=True)  # what a killed server left behind
        incoming.mkdir(parents=True, exist_ok=True)
        remove_partial_uploads(upload_dir)

    def attach(
        self,
        gui: viser.GuiApi,
        button: viser.GuiUploadButtonHandle,
        tab_id: int,
        deliver: Callable[[str, Path], None],
        refuse: Callable[[str], None],
        browser: str | None = None,
    ) -> None:
        """Receive `button`'s uploads: `deliver(name, path)` gets each complete file (it owns
        the file from then on), `refuse(message)` each refusal. Tabs of one `browser` have one
        upload in flight between them."""
        with self._lock:
            self._buttons[upload_button_id(button)] = _Button(tab_id, deliver, refuse, browser)
            interface = self._interfaces.get(id(gui))
            if interface is None:
                handlers = take_over_uploads(gui, self._start, self._part)
                interface = self._interfaces[id(gui)] = _Interface(handlers)
            interface.tab_ids.add(tab_id)

    def forget_tab(self, tab_id: int) -> None:
        """A tab closed: end its transfers (deleting their files) and forget its buttons."""
        with self._lock:
            for uuid in [uuid for uuid, button in self._buttons.items() if button.tab_id == tab_id]:
                del self._buttons[uuid]
            ended = [key for key, transfer in self._transfers.items() if transfer.tab_id == tab_id]
            for key in ended:
                _discard(self._transfers.pop(key))
            released = []
            for key, interface in list(self._interfaces.items()):
                interface.tab_ids.discard(tab_id)
                if not interface.tab_ids:
                    released.append(self._interfaces.pop(key).handlers)
        for handlers in released:
            handlers.release()

    def in_flight(self) -> int:
        """Transfers in progress."""
        with self._lock:
            return len(self._transfers)

    def _end_stalled(self) -> list[_Button]:
        """End the transfers that sent nothing for `idle_seconds` (called under the lock):
        their files are deleted and their space counts no more; their buttons, to tell."""
        now = self.clock()
        stalled = [
            key
            for key, transfer in self._transfers.items()
            if now - transfer.last_seen > self.limits.idle_seconds
        ]
        told = []
        for key in stalled:
            transfer = self._transfers.pop(key)
            _discard(transfer)
            button = self._buttons.get(transfer.button)
            if button is not None:
                told.append(button)
        return told

    def _problem(self, button: _Button, name: str, declared: int) -> str | None:
        """Why a transfer must be refused at its start (called under the lock)."""
        limits = self.limits
        suffix = Path(safe_file_name(name)).suffix.lower()
        if suffix != ".zip" and suffix not in VIDEO_SUFFIXES:
            return f"cannot use {name!r}: upload a video or a .zip of images"
        if declared <= 0:
            return "the uploaded file is empty"
        if declared > limits.max_upload_bytes:
            return (
                f"the upload is {declared / 1e6:.0f} MB; the limit is "
                f"{limits.max_upload_bytes / 1e6:.0f} MB"
            )
        if any(
            transfer.tab_id == button.tab_id
            or (button.browser is not None and transfer.browser == button.browser)
            for transfer in self._transfers.values()
        ):
            return "an upload from this browser is still arriving; wait for it to finish"
        pending = sum(transfer.declared for transfer in self._transfers.values())
        if folder_bytes(self.upload_dir) + pending + declared > limits.max_upload_dir_bytes:
            return (
                f"the uploads folder would exceed its quota of "
                f"{limits.max_upload_dir_bytes / 1e9:.1f} GB; ask the server's owner to clear it"
            )
        free = shutil.disk_usage(self.incoming).free
        if free < pending + declared + limits.free_space_reserve:
            return "the server's disk has no room for this upload"
        return None

    def _start(self, handlers: UploadHandlers, client_id: int, message: UploadStart) -> None:
        with self._lock:
            button = self._buttons.get(message.source_component_uuid)
            if button is None or button.tab_id != client_id:
                return
            stalled = self._end_stalled()
            problem = self._problem(button, message.filename, message.size_bytes)
            if problem is None:
                path = self.incoming / f"{os.getpid()}-{safe_file_name(message.transfer_uuid)}.part"
                try:
                    sink = open(path, "xb")  # noqa: SIM115 (closed when the transfer ends)
                except OSError as error:
                    problem = f"cannot receive the upload ({error.strerror})"
                else:
                    self._transfers[message.transfer_uuid] = _Transfer(
                        button.tab_id,
                        button.browser,
                        message.source_component_uuid,
                        message.filename,
                        message.size_bytes,
                        message.part_count,
                        path,
                        sink,
                        last_seen=self.clock(),
                    )
        for idle in stalled:
            idle.refuse(STALLED)
        if problem is not None:
            acknowledge_upload(handlers, message.source_component_uuid, message.transfer_uuid, 1, 1)
            button.refuse(problem)

    def _part(self, handlers: UploadHandlers, client_id: int, message: UploadPart) -> None:
        with self._lock:
            transfer = self._transfers.get(message.transfer_uuid)
            if transfer is None or transfer.tab_id != client_id:
                return
            button = self._buttons.get(transfer.button)
            size = len(message.content)
            problem = None
            done = False
            if (
                message.part_index != transfer.next_part
                or transfer.next_part >= transfer.part_count
            ):
                problem = "the upload arrived out of order; refused"
            elif transfer.received + size > transfer.declared:
                problem = "the upload is larger than it declared; refused"
            else:
                try:
                    transfer.sink.write(message.content)
                except OSError as error:
                    problem = f"cannot store the upload ({error.strerror}); refused"
            if problem is None:
                transfer.received += size
                transfer.next_part += 1
                transfer.last_seen = self.clock()
                done = transfer.next_part == transfer.part_count
                if done and transfer.received != transfer.declared:
                    problem = "the upload is smaller than it declared; refused"
            if problem is not None or done:
                del self._transfers[message.transfer_uuid]
                if problem is not None:
                    _discard(transfer)
                else:
                    transfer.sink.close()
        acknowledge_upload(
            handlers, transfer.button, message.transfer_uuid, transfer.received, transfer.declared
        )
        if button is None:
            if problem is None and done:
                transfer.path.unlink(missing_ok=True)
        elif problem is not None:
            button.refuse(problem)
        elif done:
            button.deliver(transfer.name, transfer.path)


def _discard(transfer: _Transfer) -> None:
    """Close and delete a transfer's file."""
    with contextlib.suppress(OSError):
        transfer.sink.close()
    transfer.path.unlink(missing_ok=True)
