"""The helper that compiles a cold cache's kernels from the other end (`compile_ahead` starts
`compile_helper`): it must call exactly the kernel signatures a tracker calls, so that it never
writes a cache entry the tracker would not, and it must start, once, at a process's first
compilation."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from autotrack.params import preset
from autotrack.tracker.backend import compile_ahead

# In a fresh process: the helper's calls ("helper"), then a tracker's first four frames, or the
# tracker's alone ("tracker"); prints the signatures each kernel has after the helper and those
# the tracker added to them.
_HELPER_THEN_TRACKER = """
import importlib, json, pkgutil, sys
import numpy as np
import autotrack.tracker.backend as package
from autotrack import AutoTrack, preset
from autotrack.tracker.compile_helper import compile_in_reverse

def signatures():
    found = {}
    for info in pkgutil.iter_modules(package.__path__):
        module = importlib.import_module(f"{package.__name__}.{info.name}")
        for name, value in vars(module).items():
            if hasattr(value, "py_func") and hasattr(value, "signatures"):
                found[f"{info.name}.{name}"] = {str(s) for s in value.signatures}
    return found

name, colour = sys.argv[1], sys.argv[2] == "colour"
if sys.argv[3] == "helper":
    compile_in_reverse(preset(name), colour)
helped = signatures()
frame = np.random.default_rng(1).integers(0, 255, (240, 320, 3), dtype=np.uint8)
frame = frame if colour else np.ascontiguousarray(frame[:, :, 0])
tracker = AutoTrack(preset(name))
tracker.init(frame, (100, 80, 40, 30))
for shift in (1, 2, 3):
    tracker.update(np.roll(frame, shift, axis=1))
added = {kernel: sorted(sigs - helped[kernel]) for kernel, sigs in signatures().items()}
print(json.dumps({
    "helped": {kernel: sorted(sigs) for kernel, sigs in helped.items() if sigs},
    "added": {kernel: sigs for kernel, sigs in added.items() if sigs},
}))
"""


def _signatures(name: str, mode: str, helper: bool) -> dict:
    env = dict(os.environ, **{compile_ahead.ENV_SWITCH: "0"})
    order = "helper" if helper else "tracker"
    done = subprocess.run(
        [sys.executable, "-c", _HELPER_THEN_TRACKER, name, mode, order],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.splitlines()[-1])


@pytest.mark.parametrize(("name", "mode"), [("autotrack", "colour"), ("autotrack+", "grey")])
def test_the_helper_calls_every_kernel_signature_the_tracker_calls(name: str, mode: str) -> None:
    helped = _signatures(name, mode, helper=True)
    assert helped["added"] == {}, f"the tracker compiled kernels the helper did not: {helped}"
    # ... and of the kernels a tracker calls, no signature it does not (the two processes would
    # then write two entries of one kernel's cache index at once)
    tracked = _signatures(name, mode, helper=False)["added"]
    for kernel in set(tracked) & set(helped["helped"]):
        assert helped["helped"][kernel] == tracked[kernel], kernel


def test_the_helper_starts_once_at_the_first_compilation_and_completes() -> None:
    listener = compile_ahead.HelperAtFirstCompile(preset("autotrack"), colour=True)
    assert listener.helper is None  # armed: nothing runs before a compilation
    listener.on_start(None)
    helper = listener.helper
    assert helper is not None
    listener.on_start(None)  # a second compilation starts no second helper
    assert listener.helper is helper
    assert helper.wait(timeout=600) == 0
