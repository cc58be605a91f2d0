"""Interleaved A/B of a second process's time to its first tracked frame: this checkout against
a git revision.

The revision's `autotrack/` is unpacked as it is (`ab_tracker.unpack_revision`) into a
temporary folder. Each side has its own kernel cache, FFTW wisdom and user cache, filled
beforehand by a first process (it compiles the kernels and searches the FFT plans) and one
second process; then `--pairs` pairs of fresh processes, one of each side in alternating order,
run `speed.py`'s first-frame script (building5: import, read two frames, init, one update).
The host's speed drifts from one second to the next (docs/history.md, round 15), so only
the interleaved pairs compare; the figures are every run and the medians.

python benchmarks/ab_startup.py 7abd726
python benchmarks/ab_startup.py HEAD~1 --pairs 12
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
from pathlib import Path

from ab_tracker import ROOT, revision_parser, unpack_revision
from speed import time_to_first_frame


def main() -> int:
    parser = revision_parser(__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=8, help="interleaved pairs of processes")
    args = parser.parse_args()
    if args.pairs < 1:
        print("--pairs must be at least 1", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as scratch:
        base_tree = Path(scratch, "tree")
        if not unpack_revision(args.revision, base_tree):
            return 2
        sides = {args.revision: base_tree, "this checkout": ROOT}
        caches = {name: Path(scratch, f"cache-{index}") for index, name in enumerate(sides)}
        for name, tree in sides.items():
            print(f"filling the caches of {name} (a first and a second process)", flush=True)
            for _ in range(2):
                time_to_first_frame(caches[name], tree)
        times: dict[str, list[float]] = {name: [] for name in sides}
        for pair in range(args.pairs):
            order = list(sides) if pair % 2 == 0 else list(sides)[::-1]
            for name in order:
                times[name].append(time_to_first_frame(caches[name], sides[name]))
            print(f"  pair {pair + 1}/{args.pairs}", end="\r", file=sys.stderr, flush=True)
    load = os.getloadavg()[0]
    print(f"\nsecond process, time to first tracked frame ({args.pairs} interleaved pairs):")
    for name, values in times.items():
        runs = " ".join(f"{value:.2f}" for value in values)
        print(f"  {name:<14} median {statistics.median(values):.3f} s  (runs {runs})")
    base, new = (statistics.median(values) for values in times.values())
    print(f"  saved {base - new:+.3f} s a process (load average after: {load:.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
