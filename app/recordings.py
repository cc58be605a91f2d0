"""The one thing tabs share at run time: which session files are being recorded, by which tab.

A tab must not reopen (and so continue) a file another tab is still writing.
"""

from __future__ import annotations

import threading
from pathlib import Path


class RecordingRegistry:
    """Session files being written now -> the id of the tab writing each (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._writers: dict[Path, int] = {}

    def claim(self, path: Path, tab_id: int) -> None:
        """Note that tab `tab_id` writes the session file `path`."""
        with self._lock:
            self._writers[path.resolve()] = tab_id

    def release(self, path: Path) -> None:
        """The session file `path` is closed."""
        with self._lock:
            self._writers.pop(path.resolve(), None)

    def writer_of(self, path: Path) -> int | None:
        """The tab writing `path` right now, if any."""
        with self._lock:
            return self._writers.get(path.resolve())
