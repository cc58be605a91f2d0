"""What a tab needs from its browser besides GUI and scene handles: messages, downloads,
the canvas size and the viewing camera. One implementation wraps a viser client."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np
import viser


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

    def look_at(self, position: np.ndarray, target: np.ndarray, up: np.ndarray) -> None:
        """Move the tab's viewing camera."""


class ViserClientChannel:
    """`ClientChannel` over a connected viser client."""

    def __init__(self, client: viser.ClientHandle) -> None:
        self.client = client

    def notify(self, title: str, body: str, *, error: bool = False) -> None:
        self.client.add_notification(
            title,
            body,
            auto_close_seconds=None if error else 4.0,
            color="red" if error else None,
        )

    def download(self, file_name: str, content: bytes) -> None:
        self.client.send_file_download(file_name, content, save_immediately=True)

    def canvas_size(self) -> tuple[int, int] | None:
        # viser reports a client as connected only after its first camera message.
        camera = self.client.camera
        return (camera.image_width, camera.image_height)

    def on_canvas_change(self, callback: Callable[[], None]) -> None:
        self.client.camera.on_update(lambda _camera: callback())

    def look_at(self, position: np.ndarray, target: np.ndarray, up: np.ndarray) -> None:
        with self.client.atomic():
            self.client.camera.up_direction = tuple(float(v) for v in up)
            self.client.camera.position = tuple(float(v) for v in position)
            self.client.camera.look_at = tuple(float(v) for v in target)
