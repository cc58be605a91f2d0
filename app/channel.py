"""What a tab needs from its browser besides GUI and scene handles: messages, downloads,
the canvas size and the viewing camera. One implementation wraps a viser client."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Protocol

import numpy as np
import viser

NOTE_SECONDS = 4.0
"""How long a note (a download sent, a session saved) stays on screen."""
ERROR_SECONDS = 15.0
"""How long an error stays on screen (the status line keeps it afterwards)."""


class ClientChannel(Protocol):
    """The per-tab browser connection, as the app uses it."""

    def notify(self, title: str, body: str, *, error: bool = False) -> None:
        """Show a message to this tab's user."""

    def download(self, file_name: str, content: bytes) -> None:
        """Offer `content` to this tab's browser as a file download."""

    def canvas_size(self) -> tuple[int, int] | None:
        """The 3-D canvas size in device pixels (width, height), None until known."""

    def on_canvas_change(self, callback: Callable[[], None]) -> None:
        """Call `callback` whenever the canvas size or the camera changes."""

    def field_of_view(self) -> float | None:
        """The viewing camera's vertical angle in radians, None until known."""

    def look_at(self, position: np.ndarray, target: np.ndarray, up: np.ndarray) -> None:
        """Move the tab's viewing camera."""


class ViserClientChannel:
    """`ClientChannel` over a connected viser client."""

    def __init__(self, client: viser.ClientHandle) -> None:
        self.client = client
        self._last_error: viser.NotificationHandle | None = None
        self._errors = threading.Lock()  # the worker and viser's threads both report errors

    def notify(self, title: str, body: str, *, error: bool = False) -> None:
        """A note closes after NOTE_SECONDS; an error replaces the previous error and closes
        after ERROR_SECONDS (the status line keeps it), so errors never pile up over the canvas
        where boxes are drawn."""
        handle = self.client.add_notification(
            title,
            body,
            auto_close_seconds=ERROR_SECONDS if error else NOTE_SECONDS,
            color="red" if error else None,
        )
        if error:
            with self._errors:
                previous, self._last_error = self._last_error, handle
            if previous is not None:
                previous.remove()

    def download(self, file_name: str, content: bytes) -> None:
        self.client.send_file_download(file_name, content, save_immediately=True)

    def canvas_size(self) -> tuple[int, int] | None:
        # viser reports a client as connected only after its first camera message.
        camera = self.client.camera
        size = (camera.image_width, camera.image_height)
        return size if min(size) > 0 else None  # a canvas of no size: as if not yet known

    def on_canvas_change(self, callback: Callable[[], None]) -> None:
        self.client.camera.on_update(lambda _camera: callback())

    def field_of_view(self) -> float | None:
        return float(self.client.camera.fov)

    def look_at(self, position: np.ndarray, target: np.ndarray, up: np.ndarray) -> None:
        with self.client.atomic():
            self.client.camera.up_direction = tuple(float(v) for v in up)
            self.client.camera.position = tuple(float(v) for v in position)
            self.client.camera.look_at = tuple(float(v) for v in target)
