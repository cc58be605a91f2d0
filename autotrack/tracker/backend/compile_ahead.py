"""A cold kernel cache compiled from both ends (issue 39 item 5).

On a fresh install a tracker's first frames compile its twenty-odd numba kernels one after the
other (10-25 s of one core, by the machine). At the first kernel a process has to compile, `arm` starts one
helper process that compiles the same kernels, for the same parameters and colour mode, in the
reverse order of their first use (the third frame's first, the first frame's sampling last) on
the other core. Both processes write numba's on-disk cache, and the tracker then loads the
kernels the helper finished instead of compiling them: the two meet in the middle. The machine
code is the same either way, so the boxes do not depend on it.

The helper compiles exactly the signatures the tracker calls (tests/test_compile_ahead.py), so
the two processes only ever write the same cache entry for a kernel, never two different ones.
It starts only where there is a second core, never inside a helper, and not at all with
AUTOTRACK_COMPILE_AHEAD=0.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys

from numba.core import event

from autotrack.params import TrackerParams

HELPER_MODULE = "autotrack.tracker.compile_helper"
"""The helper's module, run as `python -m` (it builds a tracker, so this module, which the
backends import, cannot import it)."""

ENV_SWITCH = "AUTOTRACK_COMPILE_AHEAD"
"""Environment variable: "0" keeps a process from starting the helper (the helper has it)."""


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity on this platform
        return os.cpu_count() or 1


class HelperAtFirstCompile(event.Listener):
    """Starts the helper at the first numba compilation of this process (a cache miss: with a
    warm cache numba loads the kernels and no compilation starts)."""

    def __init__(self, params: TrackerParams, colour: bool) -> None:
        self.params, self.colour = params, colour
        self.helper: subprocess.Popen | None = None

    def on_start(self, record: event.Event) -> None:
        if self.helper is not None:
            return
        # The helper imports this package as this process does (an uninstalled checkout too).
        path = os.pathsep.join(entry for entry in sys.path if entry)
        env = dict(os.environ, **{ENV_SWITCH: "0", "PYTHONPATH": path})
        self.helper = subprocess.Popen(
            [sys.executable, "-m", HELPER_MODULE],
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
        )
        assert self.helper.stdin is not None
        with self.helper.stdin:
            pickle.dump((self.params, self.colour), self.helper.stdin)

    def on_end(self, record: event.Event) -> None:
        pass


_listener: HelperAtFirstCompile | None = None  # one helper per process at most


def arm(params: TrackerParams, colour: bool) -> None:
    """Start the helper at this process's first kernel compilation, if any (once per process;
    a no-op on one core, in a helper, or with AUTOTRACK_COMPILE_AHEAD=0)."""
    global _listener
    if _listener is not None or os.environ.get(ENV_SWITCH) == "0" or _cores() < 2:
        return
    _listener = HelperAtFirstCompile(params, colour)
    event.register("numba:compile", _listener)
