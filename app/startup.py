"""What the server does before the first box can be tracked, shown while it happens: the
tracker's kernels compiled (or loaded from numba's cache) in a background thread, with a
notice every tab shows, with the seconds elapsed, until it is done.

A first run on a machine compiles every kernel (~12 s on a quiet 2-core machine, up to a minute
on a busy one); later starts load them from numba's cache in about a second. A box drawn
meanwhile waits for the compiler, so the page says so instead of showing a bare spinner.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from autotrack.tracker.parallel.warmup import warm_up

TICK_SECONDS = 1.0
"""How often the notice's elapsed time is shown again."""
FIRST_RUN_SECONDS = "~12-60 s"
"""What a first run's compilation takes (a quiet 2-core machine to a busy one)."""


class KernelWarmUp:
    """Runs `warm` (the tracker's warm-up) in a background thread and tells each subscriber
    the notice to show (empty once done), once a second while it runs."""

    def __init__(
        self,
        warm: Callable[[], object] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._clock = clock
        self.started = clock()
        self.finished: float | None = None
        """When the warm-up ended (None: still running)."""
        self.error = ""
        """Why the warm-up failed ('' if it did not: the first box then compiles instead)."""
        self._warm = warm or warm_up
        self._lock = threading.Lock()
        self._shows: dict[int, Callable[[str], None]] = {}
        self._next_id = 0
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="kernel-warm-up", daemon=True)
        self._thread.start()
        self._ticker = threading.Thread(target=self._tick, name="warm-up-notice", daemon=True)
        self._ticker.start()

    @property
    def running(self) -> bool:
        """Whether the kernels are still being prepared."""
        return not self._done.is_set()

    def is_alive(self) -> bool:
        """Whether the warm-up thread still runs (as threading.Thread.is_alive)."""
        return self._thread.is_alive()

    def join(self, timeout: float | None = None) -> None:
        """Wait for the warm-up to end (as threading.Thread.join)."""
        self._thread.join(timeout)

    def elapsed(self) -> float:
        """Seconds since the warm-up started (until it ended, once it did)."""
        end = self.finished if self.finished is not None else self._clock()
        return end - self.started

    def notice(self) -> str:
        """The page's notice while the kernels are prepared ('' once they are)."""
        if not self.running:
            return ""
        return (
            f"⏳ **Preparing the tracker**: compiling its kernels… {self.elapsed():.0f} s so "
            f"far (the first run on a machine takes {FIRST_RUN_SECONDS}; later starts load "
            "them from the cache in about a second). A box drawn now starts tracking once "
            "this is done."
        )

    def box_wait(self) -> str:
        """What a box drawn now waits for ('' when nothing)."""
        if not self.running:
            return ""
        return (
            f" (waiting for the tracker's kernels to compile: {self.elapsed():.0f} s so far, "
            f"{FIRST_RUN_SECONDS} on a first run)"
        )

    def subscribe(self, show: Callable[[str], None]) -> Callable[[], None]:
        """Call `show` with the notice now, each second while it runs and with '' at the end;
        returns the function that stops it (the tab closed)."""
        with self._lock:
            key = self._next_id
            self._next_id += 1
            self._shows[key] = show
        show(self.notice())

        def unsubscribe() -> None:
            with self._lock:
                self._shows.pop(key, None)

        return unsubscribe

    def _run(self) -> None:
        try:
            self._warm()
        except Exception as error:  # the first box compiles instead; say why in the log
            self.error = f"{type(error).__name__}: {error}"
        finally:
            self.finished = self._clock()
            self._done.set()

    def _tick(self) -> None:
        while not self._done.wait(TICK_SECONDS):
            self._tell(self.notice())
        self._tell("")

    def _tell(self, text: str) -> None:
        with self._lock:
            shows = list(self._shows.values())
        for show in shows:
            try:
                show(text)
            except Exception:  # a tab going away must not stop the others' notices
                continue
