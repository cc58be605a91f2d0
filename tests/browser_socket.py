"""A browser tab without a browser: a websocket client speaking viser's wire format.

It connects as the app's page does (token cookie, browser cookie, viser's subprotocol), sends
the first camera message (viser then reports the client connected and the app opens a tab for
it), decodes every message the server sends on a background thread, and can send any client
message as the browser would (a dict with its message type, msgpack-encoded). Closing it is a
tab closed by its user: viser's disconnect path runs, as with Chromium.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import msgspec
import viser
import websockets.sync.client as ws_client
import zstandard
from websockets.exceptions import ConnectionClosed

CAMERA = {
    "type": "ViewerCameraMessage",
    "wxyz": (1.0, 0.0, 0.0, 0.0),
    "position": (0.0, 0.0, 5.0),
    "fov": 0.9,
    "near": 0.01,
    "far": 100.0,
    "look_at": (0.0, 0.0, 0.0),
    "up_direction": (0.0, 0.0, 1.0),
}
"""The camera message a page sends once its canvas is laid out (size added per tab)."""


def decode_window(raw: bytes) -> list[dict]:
    """The messages of one server window: [8 bytes msgpack size][8 bytes compressed size]
    [zstd msgpack]... (binary buffers after it are left out)."""
    size = int.from_bytes(raw[:8], "little")
    compressed = int.from_bytes(raw[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(raw[16 : 16 + compressed], size)
    return list(msgspec.msgpack.decode(inner)["messages"])


class SocketBrowser:
    """One tab's websocket, as the page opens it."""

    def __init__(
        self,
        port: int,
        *,
        token: str | None = None,
        browser: str | None = "b" * 32,
        canvas: tuple[int, int] = (800, 600),
    ) -> None:
        cookies = [] if token is None else [f"autotrack_token_{port}={token}"]
        if browser is not None:
            cookies.append(f"autotrack_browser_{port}={browser}")
        self.connection = ws_client.connect(
            f"ws://127.0.0.1:{port}/",
            subprotocols=[f"viser-v{viser.__version__}"],
            additional_headers={"Cookie": "; ".join(cookies)},
            open_timeout=60,
            max_size=None,
        )
        self.received: list[dict] = []
        self._lock = threading.Lock()
        self._reader = threading.Thread(target=self._read, name="socket-browser", daemon=True)
        self._reader.start()
        width, height = canvas
        self.send({**CAMERA, "image_width": width, "image_height": height})

    def _read(self) -> None:
        try:
            for raw in self.connection:
                if isinstance(raw, bytes):
                    messages = decode_window(raw)
                    with self._lock:
                        self.received.extend(messages)
        except ConnectionClosed:
            return

    def send(self, message: dict) -> None:
        """Send one client message (a dict with "type" and the message's fields)."""
        self.connection.send(msgspec.msgpack.encode(message))

    def messages(self, kind: str) -> list[dict]:
        """The messages of one type received so far."""
        with self._lock:
            return [message for message in self.received if message.get("type") == kind]

    def wait_for(self, predicate: Callable[[], bool], timeout: float = 60.0) -> None:
        """Wait (generously) until `predicate()` holds."""
        deadline = time.monotonic() + timeout
        while not predicate():
            assert time.monotonic() < deadline, "the server never got there"
            time.sleep(0.02)

    def close(self) -> None:
        """Close the tab (its websocket), as a user closing it does."""
        self.connection.close()
        self._reader.join(timeout=30)

    def __enter__(self) -> SocketBrowser:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()
