"""Interleaved A/B of whole end-to-end runs (four targets + pose): this checkout against a git
revision, each run in a fresh process.

`ab_localize.py` alternates the two versions frame by frame in one process, which times one
thread well; with tracking processes (`--processes 2`, the default configuration on two cores)
one version's children would then track while the other version's frame is timed. Here each
run is a whole `localize_sequence` over the speed benchmark's rendered 1280x720 sequence in its
own interpreter (the revision's `autotrack/` first on its import path, its children too), the
two versions alternating run by run, so a slow spell of a shared machine hits both alike.
Prints every run's rate and CPU time per frame (the parent process, read-ahead included, and
its children), the medians, and whether every box and pose is identical. Each version plans
its FFTs from a wisdom file of its own (made in its first run's warm-up), so a version that
plans differently runs its own plans, not the other's.

python benchmarks/ab_runs.py integration3
python benchmarks/ab_runs.py HEAD~1 --runs 4 --processes 1
"""

from __future__ import annotations

import inspect
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from ab_tracker import ROOT, revision_parser, unpack_revision
from speed import _children_cpu, render_multi_sequence

RUN = (
    """
import json, os, sys, time
from pathlib import Path
import cv2, numpy as np
import scipy.optimize  # imported before the clock, as speed.py does
import autotrack
from autotrack.io.frames import open_frames
from autotrack.localization.scene import load_scene
from autotrack.params import preset
from autotrack.pipeline import localize_sequence
from autotrack.tracker.parallel.target_process import WorkerPool

"""
    + inspect.getsource(_children_cpu)
    + """
sequence, out, processes = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
cv2.setNumThreads(1)
scene = load_scene(sequence / "scene.json")
boxes = json.loads((sequence / "boxes.json").read_text())
params = preset("autotrack")
with WorkerPool() as pool:
    with open_frames(sequence) as source:
        first = [source.read(i) for i in range(3)]
        list(localize_sequence(first, scene, boxes, params, processes=processes, worker_pool=pool))
        for index in range(len(source)):
            source.read_bgr(index)
    with open_frames(sequence) as source:
        wall, cpu, children = time.perf_counter(), time.process_time(), _children_cpu()
        records = list(
            localize_sequence(source, scene, boxes, params, processes=processes, worker_pool=pool)
        )
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        children = _children_cpu() - children
n = len(records)
np.savez(
    out,
    boxes=np.array([[r.tracks[k].box for k in sorted(r.tracks)] for r in records]),
    position=np.array([r.pose.position for r in records]),
    rotation=np.array([r.pose.rotation for r in records]),
)
print(json.dumps({"package": os.path.dirname(autotrack.__file__), "rate": n / wall,
                  "cpu_ms": cpu / n * 1e3, "children_ms": children / n * 1e3}))
"""
)


def run_side(
    root: Path, sequence: Path, out: Path, processes: int, workdir: Path, wisdom: Path
) -> dict:
    """One whole run with `root`'s `autotrack` package (started in `workdir`, so that no
    checkout's package is found through the current directory) and `wisdom` as its FFTW
    wisdom file."""
    env = dict(os.environ, PYTHONPATH=str(root), AUTOTRACK_FFTW_WISDOM=str(wisdom))
    completed = subprocess.run(
        [sys.executable, "-c", RUN, str(sequence), str(out), str(processes)],
        cwd=workdir,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    result = json.loads(completed.stdout.strip().splitlines()[-1])
    if Path(result["package"]).resolve() != (root / "autotrack").resolve():
        raise RuntimeError(f"ran {result['package']}, not {root / 'autotrack'}")
    return result


def identical(a: Path, b: Path) -> bool:
    first, second = np.load(a), np.load(b)
    return all(np.array_equal(first[k], second[k], equal_nan=True) for k in first.files)


def main() -> int:
    parser = revision_parser(__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="whole runs per version")
    parser.add_argument("--frames", type=int, default=300, help="frames of the sequence")
    parser.add_argument("--processes", type=int, default=2, help="tracking processes per run")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        if not unpack_revision(args.revision, work / "base"):
            return 2
        sequence = render_multi_sequence(work, args.frames)
        sides = {args.revision: work / "base", "this": ROOT}
        runs: dict[str, list[dict]] = {name: [] for name in sides}
        load = os.getloadavg()
        print(f"load average before: {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}", flush=True)
        same = True
        for index in range(args.runs):
            order = list(sides) if index % 2 == 0 else list(sides)[::-1]
            for name in order:
                side = "base" if name != "this" else "this"
                out, wisdom = work / f"{index}-{side}.npz", work / f"fftw-{side}.json"
                result = run_side(sides[name], sequence, out, args.processes, work, wisdom)
                runs[name].append(result)
                print(
                    f"  {name:<14} {result['rate']:5.1f} frames/s, CPU {result['cpu_ms']:.1f} "
                    f"ms/frame here + {result['children_ms']:.1f} in the children",
                    flush=True,
                )
            same &= identical(work / f"{index}-base.npz", work / f"{index}-this.npz")
        load = os.getloadavg()
        print(f"load average after: {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}")
    for name, results in runs.items():
        rates = [r["rate"] for r in results]
        print(
            f"  {name:<14} median {statistics.median(rates):5.1f} frames/s "
            f"(runs {' '.join(f'{r:.1f}' for r in rates)}), CPU "
            f"{statistics.median(r['cpu_ms'] for r in results):.1f} + "
            f"{statistics.median(r['children_ms'] for r in results):.1f} ms/frame"
        )
    print(f"  boxes and poses {'identical' if same else 'DIFFERENT'} in every pair of runs")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
