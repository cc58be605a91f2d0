"""Writes the app makes to a tab's widgets without firing that tab's own on_update callbacks
(a value the app shows is not a user's edit)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import viser


class QuietWrites:
    """Writes to widgets that do not fire this tab's own on_update callbacks."""

    def __init__(self) -> None:
        self._local = threading.local()

    def set(self, handle: Any, attribute: str, value: Any) -> None:
        """`handle.attribute = value`, without triggering the callbacks wrapped by `user_edit`."""
        self._local.active = True
        try:
            setattr(handle, attribute, value)
        finally:
            self._local.active = False

    def set_options(self, dropdown: viser.GuiDropdownHandle, options: tuple[str, ...]) -> None:
        """A dropdown's options, sent only when they changed."""
        if tuple(dropdown.options) != options:
            self.set(dropdown, "options", options)

    def user_edit(self, callback: Callable[[], None]) -> Callable[[Any], None]:
        """An on_update callback that runs `callback` unless the app itself wrote the value."""

        def on_update(_event: Any) -> None:
            if not getattr(self._local, "active", False):
                callback()

        return on_update
