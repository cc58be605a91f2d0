"""The start-up of a run is reported apart from the frame rate of the frames after it."""

from __future__ import annotations

import pytest

from autotrack.cli import timing
from autotrack.cli.timing import STARTUP_FRAMES, StartupClock


@pytest.fixture
def clock(monkeypatch) -> tuple[StartupClock, list[float]]:
    """A clock reading the times pushed onto the returned list, one per reading."""
    readings = [100.0]
    monkeypatch.setattr(timing.time, "perf_counter", lambda: readings[-1])
    return StartupClock(), readings


def _results(clock: StartupClock, readings: list[float], times: list[float]) -> None:
    for moment in times:
        readings.append(moment)
        clock.tick()


def test_the_first_frames_are_start_up_and_the_rate_counts_only_the_later_ones(clock) -> None:
    startup_clock, readings = clock
    # A first run: 55.7 s compiling on the first frame, then 10 ms a frame after the start-up.
    times = [155.7, 161.5, 171.5] + [171.5 + 0.01 * (k + 1) for k in range(100)]
    _results(startup_clock, readings, times)
    line = startup_clock.report("tracking")
    assert line.startswith("start-up 71.5 s (the first 3 frames")
    assert line.endswith("tracking 100.0 fps over 100 frames")


def test_the_rate_can_come_from_the_trackers_own_time(clock) -> None:
    startup_clock, readings = clock
    _results(startup_clock, readings, [101.0, 101.5, 102.0, 103.0, 104.0])
    assert startup_clock.report("tracking", seconds_after_startup=0.5).endswith(
        "tracking 4.0 fps over 2 frames"
    )


def test_too_few_frames_say_so_instead_of_a_rate(clock) -> None:
    startup_clock, readings = clock
    _results(startup_clock, readings, [102.0] * (STARTUP_FRAMES - 1))
    assert "too few frames to time a rate" in startup_clock.report("tracking")
    _results(startup_clock, readings, [103.0])
    assert startup_clock.report("tracking").endswith("no later frames to time")
