"""A fresh install's first run, and where its seconds go: the first 10 frames of DTB70/Gull1
tracked by a new `python` process with empty caches (numba's kernels compile), then by a second
process on the first one's caches (issue 39 item 5). The empty-cache run is made twice: as a
user gets it (a helper process compiles the kernels from the other end on the second core,
`autotrack.tracker.backend.compile_ahead`) and with the helper off (AUTOTRACK_COMPILE_AHEAD=0:
every kernel compiled one after the other by the tracking process).

The first process records numba's compile events (numba's documented event API,
`numba.core.event`) and prints the CPU seconds each kernel's compilation took, its callees'
compilation excluded, beside the wall clock from launch to the tenth frame and the process's
CPU time (on a busy machine the wall clock waits for a core; the CPU time does not, so it is
the figure to compare, and on a quiet machine the wall clock is about the CPU time).

python benchmarks/cold_start.py [--frames 10] [--top 12]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

GULL1 = Path(__file__).resolve().parents[2] / "shared" / "data" / "sequences" / "DTB70" / "Gull1"

_RUN_SCRIPT = """
import json, sys, time
from collections import defaultdict
from numba.core import event

class CompileTimes(event.Listener):  # CPU seconds a kernel's compilation, callees' excluded

    def __init__(self):
        self.own, self.count, self.stack = defaultdict(float), defaultdict(int), []
        self.nested = defaultdict(int)  # compilations inside another's (a kernel's callee)

    def on_start(self, record):
        function = record.data["dispatcher"].py_func
        name = f"{function.__module__}:{function.__qualname__}"
        if self.stack:
            self.nested[name] += 1
        self.stack.append([name, time.process_time(), 0.0])

    def on_end(self, record):
        name, start, nested = self.stack.pop()
        spent = time.process_time() - start
        self.own[name] += spent - nested
        self.count[name] += 1
        if self.stack:
            self.stack[-1][2] += spent


compiles = CompileTimes()
event.register("numba:compile", compiles)
from autotrack import AutoTrack, preset
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.io.frames import read_image

sequence = load_otb_sequence(sys.argv[1])[0]
imported = time.time()
tracker = AutoTrack(preset("autotrack"))
tracker.init(read_image(sequence.frame_paths[0]), sequence.init_box)
for path in sequence.frame_paths[1 : int(sys.argv[2])]:
    tracker.update(read_image(path))
done = time.time()
cpu = time.process_time()
figures = {"imported": imported, "done": done, "cpu": cpu, "compile": compiles.own}
print(json.dumps({**figures, "compilations": compiles.count, "nested": compiles.nested}))
"""


def run(cache: Path, frames: int, helper: bool = True) -> dict:
    """Launch a process that tracks `frames` frames of Gull1 with its caches in `cache`: its
    launch, import and end times, CPU seconds, and per compiled function ("module:name") the
    CPU seconds of its compilation ("compile"), the number of its compilations (one per
    signature, "compilations") and of those inside another function's ("nested": compiled as
    a callee of a kernel)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache / "numba"), AUTOTRACK_CACHE_DIR=str(cache))
    env["XDG_CACHE_HOME"] = str(cache / "xdg")
    if not helper:
        env["AUTOTRACK_COMPILE_AHEAD"] = "0"
    start = time.time()
    done = subprocess.run(
        [sys.executable, "-c", _RUN_SCRIPT, str(GULL1), str(frames)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    figures = json.loads(done.stdout.splitlines()[-1])
    figures["start"] = start
    return figures


def main() -> int:
    """Print the first and second process's wall clock and the first one's compile table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10)
    parser.add_argument("--top", type=int, default=12, help="kernels listed")
    args = parser.parse_args()
    if not GULL1.is_dir():
        print(f"Gull1 is not at {GULL1}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as alone, tempfile.TemporaryDirectory() as scratch:
        unhelped = run(Path(alone), args.frames, helper=False)
        first = run(Path(scratch), args.frames)
        second = run(Path(scratch), args.frames)
    print(f"{args.frames} frames of DTB70/Gull1, fresh processes (load {os.getloadavg()[0]:.1f}):")
    runs = (
        ("empty caches, helper off", unhelped),
        ("empty caches (as installed)", first),
        ("second process", second),
    )
    for label, figures in runs:
        wall = figures["done"] - figures["start"]
        imports = figures["imported"] - figures["start"]
        compiled = sum(figures["compile"].values())
        print(
            f"  {label:<28} {wall:6.2f} s wall, {figures['cpu']:6.2f} s CPU"
            f"  (launch + imports {imports:.2f} s wall; compiling {compiled:.2f} s CPU)"
        )
    print("  the kernels the helper-off process compiled, CPU seconds each:")
    ranked = sorted(unhelped["compile"].items(), key=lambda item: -item[1])
    for name, seconds in ranked[: args.top]:
        print(f"    {seconds:6.2f} s  {name.split(':')[-1]}")
    if len(ranked) > args.top:
        rest = sum(seconds for _, seconds in ranked[args.top :])
        others = f"{len(ranked) - args.top} others (numba's own numpy overloads included)"
        print(f"    {rest:6.2f} s  {others}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
