"""Interleaved A/B of `localize_sequence` (four targets + pose): this checkout against a git
revision, in one process, frame by frame.

The revision's `autotrack/` is imported as `autotrack_base` (`ab_tracker.import_revision`); both
pipelines run on the speed benchmark's rendered 1280x720 sequence (four landmarks, JPEG files
read ahead as the pipeline does), one frame each in alternating order, so a busy machine slows
both alike. Prints the medians per frame of the main thread's CPU time (`time.thread_time`),
of the part outside the trackers (pose, refinement, bookkeeping: the frame minus
`TrackerGroups.advance`) and of the wall time, and whether every box and pose is identical.
With `--processes 2` one side's children may track (speculatively, the next frame) during the
other side's frame: time the two-process wall clock with `ab_runs.py` (whole runs).

python benchmarks/ab_localize.py integration3
python benchmarks/ab_localize.py HEAD~1 --frames 150 --processes 2
"""

from __future__ import annotations

import importlib
import json
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from ab_tracker import BASE_PACKAGE, import_revision, revision_parser
from speed import render_multi_sequence


class Side:
    """One version's pipeline over the sequence, timed frame by frame."""

    def __init__(self, package: str, sequence: Path, frames: int, processes: int) -> None:
        self.name = package
        modules = {
            name: importlib.import_module(f"{package}.{name}")
            for name in ("io.frames", "localization.scene", "params", "pipeline", "pipeline.groups")
        }
        self._tracking = 0.0
        self._patch_groups(modules["pipeline.groups"].TrackerGroups)
        scene = modules["localization.scene"].load_scene(sequence / "scene.json")
        boxes = json.loads((sequence / "boxes.json").read_text())
        params = modules["params"].preset("autotrack")
        localize = modules["pipeline"].localize_sequence
        source = modules["io.frames"].open_frames(sequence)
        first = [source.read(i) for i in range(3)]
        list(localize(first, scene, boxes, params, processes=processes))  # warm-up
        self._source = source
        self._outcomes = localize(source, scene, boxes, params, processes=processes)
        self.frames = frames
        self.cpu: list[float] = []
        self.outside: list[float] = []
        self.wall: list[float] = []

    def _patch_groups(self, groups: type) -> None:
        advance = groups.advance
        side = self

        def timed(self, *args, **kwargs):
            started = time.thread_time()
            try:
                return advance(self, *args, **kwargs)
            finally:
                side._tracking += time.thread_time() - started

        groups.advance = timed

    def step(self):
        """The next frame's outcome, timed."""
        self._tracking = 0.0
        wall, cpu = time.perf_counter(), time.thread_time()
        outcome = next(self._outcomes)
        cpu = time.thread_time() - cpu
        self.wall.append(time.perf_counter() - wall)
        self.cpu.append(cpu)
        self.outside.append(cpu - self._tracking)
        return outcome

    def close(self) -> None:
        self._outcomes.close()
        self._source.close()


def same_outcome(a, b) -> bool:
    """Boxes, poses and the solver's reasons identical (NaN equal to NaN)."""
    if a.frame_index != b.frame_index or set(a.tracks) != set(b.tracks):
        return False
    for key, result in a.tracks.items():
        other = b.tracks[key]
        if tuple(result.box) != tuple(other.box) or not _same(result.peak_score, other.peak_score):
            return False
    if (a.pose is None) != (b.pose is None):
        return False
    if a.pose is None:
        return True
    p, q = a.pose, b.pose
    return (
        p.valid == q.valid
        and np.array_equal(p.rotation, q.rotation, equal_nan=True)
        and np.array_equal(p.position, q.position, equal_nan=True)
        and p.reason == q.reason
        and p.used_landmarks == q.used_landmarks
        and _same(p.rms_error_px, q.rms_error_px)
        and _same(p.position_std_m, q.position_std_m)
        and p.excluded_landmarks == q.excluded_landmarks
        and all(
            _same(p.reprojection_errors[k], q.reprojection_errors[k]) for k in p.reprojection_errors
        )
    )


def _same(x: float, y: float) -> bool:
    return x == y or (math.isnan(x) and math.isnan(y))


def main() -> int:
    parser = revision_parser(__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300, help="frames of the sequence")
    parser.add_argument("--processes", type=int, default=1, help="tracking processes per side")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as folder:
        if not import_revision(args.revision, Path(folder) / "base"):
            return 2
        sequence = render_multi_sequence(Path(folder), args.frames)
        sides = [
            Side(name, sequence, args.frames, args.processes)
            for name in (BASE_PACKAGE, "autotrack")
        ]
        load = os.getloadavg()
        print(f"load average before: {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}")
        identical = True
        try:
            for index in range(args.frames - 1):
                order = sides if index % 2 == 0 else sides[::-1]
                outcomes = {side.name: side.step() for side in order}
                identical &= same_outcome(*outcomes.values())
        finally:
            for side in sides:
                side.close()
    for side, label in zip(sides, (args.revision, "this"), strict=True):
        print(
            f"  {label:<14} main thread CPU {statistics.median(side.cpu) * 1e3:6.3f} ms a frame, "
            f"outside the trackers {statistics.median(side.outside) * 1e3:6.3f} ms "
            f"(slowest frame {max(side.outside) * 1e3:.1f} ms), "
            f"wall {statistics.median(side.wall) * 1e3:6.3f} ms"
        )
    base, new = sides
    ratio = statistics.median(base.outside) / statistics.median(new.outside)
    print(
        f"  outside the trackers: ratio {ratio:.3f}; boxes and poses "
        f"{'identical' if identical else 'DIFFERENT'} on {args.frames - 1} frames"
    )
    return 0 if identical else 1


if __name__ == "__main__":
    sys.exit(main())
