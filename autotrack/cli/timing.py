"""The start-up of a run reported apart from its frame rate.

The first frames of a process cost far more than the rest: numba compiles the kernels on a first
run (about a minute on two cores; loaded from the cache in a fraction of a second afterwards),
the FFTs are planned and the first frame sets up the filters. Measured on OTB/Crossing with an
empty cache: 55.7, 5.8 and 10.0 s for the first three frames, then ~10 ms a frame; with the cache
0.50, 0.06 and 0.03 s. Counting them in the frame rate printed 0.2 fps for a first run, so they
are reported as start-up and the rate is taken over the frames after them.
"""

from __future__ import annotations

import time

STARTUP_FRAMES = 3
"""Frames counted as start-up: the first frame's set-up and the first two updates, where the
kernels are compiled (or loaded) and the FFTs planned."""


class StartupClock:
    """Wall time from a command's start to its first `STARTUP_FRAMES` results, and the frames
    after them: `tick()` at each frame's result, then `report`."""

    def __init__(self) -> None:
        self.started = time.perf_counter()
        self.frames = 0
        self.startup_done: float | None = None
        self.last = self.started

    def tick(self) -> None:
        """One more frame has its result."""
        self.frames += 1
        self.last = time.perf_counter()
        if self.frames == STARTUP_FRAMES:
            self.startup_done = self.last

    def report(self, label: str, seconds_after_startup: float | None = None) -> str:
        """'start-up 21.4 s (...) · tracking 240.3 fps over 117 frames': `label` names what the rate
        counts; `seconds_after_startup` is the time the frames after the start-up took (default:
        the wall time from the end of the start-up to the last result)."""
        if self.startup_done is None:
            return (
                f"start-up and {self.frames} frames: {self.last - self.started:.1f} s "
                f"(too few frames to time a rate: the first {STARTUP_FRAMES} are start-up)"
            )
        startup = (
            f"start-up {self.startup_done - self.started:.1f} s (the first {STARTUP_FRAMES} "
            "frames; includes compiling the kernels on a first run)"
        )
        timed = self.frames - STARTUP_FRAMES
        seconds = (
            self.last - self.startup_done
            if seconds_after_startup is None
            else seconds_after_startup
        )
        if timed == 0 or seconds <= 0:
            return f"{startup} · no later frames to time"
        return f"{startup} · {label} {timed / seconds:.1f} fps over {timed} frames"
