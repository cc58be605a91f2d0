"""A tab's worker thread: the only thread that changes the tab's state.

GUI callbacks never track: they queue a command here. The worker runs the commands one at a
time and, while the controller is playing, plays the next frame at the playback rate. An error
in a command stops playback and is reported; it never kills the thread.
"""

from __future__ import annotations

import queue
import sys
import threading
import time
import traceback
from collections.abc import Callable
from typing import Any

from autotrack.errors import AutoTrackError


class Worker:
    """Runs a tab's commands and playback on one thread.

    Args:
        is_playing: Whether to play the next frame when no command is waiting.
        play_step: Plays one frame.
        frame_period: Seconds between played frames (0: as fast as tracking goes).
        after_command: Called after each command (the panels follow the state).
        after_step: Called after each played frame.
        report: Called with a message when a command or a step fails (after playback stopped
            through `stop_playing`).
        stop_playing: Stops playback.
        name: Thread name.
    """

    def __init__(
        self,
        *,
        is_playing: Callable[[], bool],
        play_step: Callable[[], None],
        frame_period: Callable[[], float],
        after_command: Callable[[], None],
        after_step: Callable[[], None],
        report: Callable[[str], None],
        stop_playing: Callable[[], None],
        name: str,
    ) -> None:
        self._is_playing = is_playing
        self._play_step = play_step
        self._frame_period = frame_period
        self._after_command = after_command
        self._after_step = after_step
        self._report = report
        self._stop_playing = stop_playing
        self._commands: queue.Queue[Callable[[], None] | None] = queue.Queue()
        self._pending = 0
        self._idle = threading.Condition()
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def submit(self, command: Callable[..., None], *args: Any) -> None:
        """Queue `command(*args)`."""
        with self._idle:
            self._pending += 1
        self._commands.put(lambda: command(*args))

    def has_waiting(self) -> bool:
        """Whether a command is queued (long commands stop early to let it run)."""
        return not self._commands.empty()

    def wait_idle(self, timeout: float = 300.0) -> bool:
        """Block until every queued command ran and playback stopped; False on timeout."""
        deadline = time.monotonic() + timeout
        with self._idle:
            while self._pending > 0 or self._is_playing():
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._idle.wait(min(remaining, 0.5))
        return True

    def close(self, timeout: float = 30.0) -> None:
        """Stop playback and the thread, after the command running now."""
        self._stop_playing()
        self._commands.put(None)
        self._thread.join(timeout=timeout)

    def _loop(self) -> None:
        next_step = time.monotonic()
        while True:
            wait = max(0.0, next_step - time.monotonic()) if self._is_playing() else None
            try:
                command = self._commands.get(timeout=wait)
            except queue.Empty:
                started = time.monotonic()
                with self._idle:  # a step is idle only once its panels are shown too
                    self._pending += 1
                self._guarded(self._play_step, self._after_step)
                with self._idle:
                    self._pending -= 1
                    self._idle.notify_all()
                next_step = started + self._frame_period()
                continue
            if command is None:
                return
            self._guarded(command, self._after_command)
            with self._idle:
                self._pending -= 1
                self._idle.notify_all()

    def _guarded(self, command: Callable[[], None], after: Callable[[], None]) -> None:
        try:
            command()
        except AutoTrackError as error:
            self._stop_playing()
            self._report(str(error))
        except Exception as error:  # a bug must not kill the tab's worker
            self._stop_playing()
            traceback.print_exc(file=sys.stderr)
            self._report(f"internal error: {type(error).__name__}: {error}")
        try:
            after()
        except Exception:  # nor a display hiccup
            traceback.print_exc(file=sys.stderr)
        with self._idle:
            self._idle.notify_all()
