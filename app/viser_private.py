"""Every use of viser's internals, for the few things viser has no public hook for.

The app needs four things viser (checked on the versions in `CHECKED_VERSIONS`) offers no public
API for; each is one small function here, and nothing else in the app touches a private name
of viser:

- receiving uploads as a stream (`take_over_uploads`, `acknowledge_upload`,
  `upload_button_id`): viser's upload button keeps every part in memory for a size the client
  only declares (app/uploads.py says why that is not acceptable);
- sending a chart's data with nulls (`send_uplot_data`): assigning `handle.data` casts every
  series to float64, null becoming NaN, which uPlot draws as a line across the gap;
- reading the websocket handshake of a client (`handshake_headers`): the browser cookie that
  says whose sessions a tab sees (app/owners.py);
- putting a check in front of viser's websocket and HTTP handshakes (`guard_handshakes`): viser
  builds its websockets server inside `ViserServer.__init__`.

`check_viser_version` refuses any other viser version at start-up (tests/test_viser_private.py
checks each function on the installed one), so a viser release that moves these internals
fails loudly instead of misbehaving.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable, Iterator, Mapping
from typing import Any

import viser
from viser._messages import FileTransferPart, FileTransferPartAck, FileTransferStartUpload

CHECKED_VERSIONS = frozenset({"1.1.1"})
"""The viser versions every function here was checked on (tests/test_viser_private.py)."""

UploadStart = FileTransferStartUpload
"""A client starting an upload (fields: source_component_uuid, transfer_uuid, filename,
mime_type, part_count, size_bytes)."""
UploadPart = FileTransferPart
"""One part of an upload (fields: source_component_uuid, transfer_uuid, part_index, content)."""

_VISER_UPLOAD_HANDLERS = {
    FileTransferStartUpload: "_handle_file_transfer_start",
    FileTransferPart: "_handle_file_transfer_part",
}
_PATCH_LOCK = threading.Lock()


def check_viser_version(version: str = viser.__version__) -> None:
    """Refuse a viser whose internals were not checked (raises RuntimeError, one line)."""
    if version not in CHECKED_VERSIONS:
        checked = ", ".join(sorted(CHECKED_VERSIONS))
        raise RuntimeError(
            f"viser {version} is installed; AutoTrack Studio was checked on viser {checked} "
            "only (app/viser_private.py): install that version"
        )


class UploadHandlers:
    """Our upload handlers installed on one websocket interface (a client's, or the server's);
    `release` gives viser its own back and drops every reference to the interface."""

    def __init__(self, gui: viser.GuiApi, interface: Any, installed: list[tuple]) -> None:
        self._gui = gui
        self._interface = interface
        self._installed = installed

    def queue(self, message: object) -> None:
        """Send a message to the interface's client(s)."""
        interface = self._interface
        if interface is not None:
            interface.queue_message(message)

    def release(self) -> None:
        """Put viser's handlers back (harmless once the client is gone) and forget the
        interface, so nothing here keeps the client's GUI, scene and callbacks alive."""
        interface, gui, self._interface, self._gui = self._interface, self._gui, None, None
        if interface is None:
            return
        for message_type, ours in self._installed:
            with contextlib.suppress(AssertionError, ValueError, KeyError):
                interface.unregister_handler(message_type, ours)
            interface.register_handler(
                message_type, getattr(gui, _VISER_UPLOAD_HANDLERS[message_type])
            )
        self._installed = []


def take_over_uploads(
    gui: viser.GuiApi,
    on_start: Callable[[UploadHandlers, int, FileTransferStartUpload], None],
    on_part: Callable[[UploadHandlers, int, FileTransferPart], None],
) -> UploadHandlers:
    """Route the upload messages of `gui`'s websocket interface to `on_start(handlers,
    client_id, message)` and `on_part(...)` instead of viser's in-memory assembly."""
    interface = gui._websock_interface  # noqa: SLF001
    registered = interface._incoming_handlers  # noqa: SLF001
    installed: list[tuple] = []
    handlers = UploadHandlers(gui, interface, installed)
    for message_type, ours in ((FileTransferStartUpload, on_start), (FileTransferPart, on_part)):
        viser_handler = getattr(gui, _VISER_UPLOAD_HANDLERS[message_type])
        if viser_handler not in registered.get(message_type, []):
            raise RuntimeError("viser's upload handlers are not where this app expects")
        interface.unregister_handler(message_type, viser_handler)
        routed = _routed(ours, handlers)
        interface.register_handler(message_type, routed)
        installed.append((message_type, routed))
    return handlers


def _routed(handler: Callable, handlers: UploadHandlers) -> Callable[[int, object], None]:
    return lambda client_id, message: handler(handlers, client_id, message)


def acknowledge_upload(
    handlers: UploadHandlers, button_id: str, transfer: str, received: int, total: int
) -> None:
    """Tell the browser's upload button how far a transfer is (it shows progress; received ==
    total ends it on the browser's side)."""
    handlers.queue(
        FileTransferPartAck(
            source_component_uuid=button_id,
            transfer_uuid=transfer,
            transferred_bytes=received,
            total_bytes=total,
        )
    )


def upload_button_id(button: viser.GuiUploadButtonHandle) -> str:
    """The id a browser names an upload button by in its upload messages."""
    return button._impl.uuid  # noqa: SLF001


def send_uplot_data(handle: viser.GuiUplotHandle, data: tuple) -> None:
    """Set a chart's data as given (None staying null), as `handle.data = ...` does minus its
    cast to float64: the handle's props and the update message."""
    state = handle._impl  # noqa: SLF001
    if state.removed:
        raise RuntimeError("the chart was removed")
    state.props.data = data
    handle._queue_update("data", data)  # noqa: SLF001


def handshake_headers(server: viser.ViserServer, client_id: int) -> Mapping[str, str] | None:
    """The HTTP headers of a connected client's websocket handshake (None if unknown)."""
    infrastructure = server._websock_server  # noqa: SLF001
    connection = infrastructure._live_connections.get(client_id)  # noqa: SLF001
    request = getattr(connection, "request", None)
    return None if request is None else request.headers


@contextlib.contextmanager
def guard_handshakes(wrap: Callable[[Callable | None], Callable]) -> Iterator[None]:
    """While the block runs (it should start exactly one viser server), the websockets server
    viser starts gets `wrap(viser's process_request)` as its `process_request`: the check runs
    before every HTTP request and websocket handshake viser answers."""
    import websockets.asyncio.server as ws_server

    with _PATCH_LOCK:
        original = ws_server.serve

        def serve(*args, process_request=None, **kwargs):  # noqa: ANN002, ANN003, ANN202
            return original(*args, process_request=wrap(process_request), **kwargs)

        ws_server.serve = serve
        try:
            yield
        finally:
            ws_server.serve = original


def deliver_as_client(server: viser.ViserServer, client_id: int, message: object) -> None:
    """Handle `message` as if client `client_id` had sent it, through viser's dispatch (how
    tabs opened on the server's own GUI are driven without a browser), and wait until done."""
    infrastructure = server._websock_server  # noqa: SLF001
    dispatch = infrastructure._handle_incoming_message(client_id, message)  # noqa: SLF001
    loop = infrastructure._background_event_loop  # noqa: SLF001
    asyncio.run_coroutine_threadsafe(dispatch, loop).result()
