"""Where a frame of four targets + pose goes: cProfile (CPU time) of `localize_sequence` on one
thread, in one process, over the speed benchmark's rendered 1280x720 sequence.

Prints the CPU milliseconds per frame of the pipeline's parts (tracking, decoding, the pose,
the rest) and the profile's largest entries by their own time. cProfile sees this thread only,
timed by its own CPU clock (`time.thread_time`): the frames `FrameCache` reads ahead are decoded
on another thread, so decoding shows as the first two frames' and the waits for a frame not
ready yet, and the decoder's CPU time is not counted in whatever this thread ran meanwhile (as
it was with the process's clock before round 16).

python benchmarks/profile_localize.py [--frames 300] [--top 30]
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import sys
import tempfile
import time
from pathlib import Path

import cv2

sys.path.insert(0, str(Path(__file__).resolve().parent))
from speed import render_multi_sequence  # noqa: E402

PARTS = (
    ("tracking (decoding included)", "groups.py", "advance"),
    ("decoding (on this thread)", "frames.py", "_read_bgr"),
    ("waiting for the frame read ahead (decoded on another thread)", "frames.py", "result"),
    ("pose", "pipeline.py", "_estimate_pose"),
    ("whole frame", "pipeline.py", "advance"),
)
"""(label, file name, function) whose cumulative time is printed per frame."""


def cumulative(stats: pstats.Stats, file_name: str, function: str) -> float:
    """Cumulative seconds of the profiled function `function` defined in `file_name`."""
    return sum(
        entry[3]
        for (path, _, name), entry in stats.stats.items()  # type: ignore[attr-defined]
        if name == function and Path(path).name == file_name
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--top", type=int, default=30)
    args = parser.parse_args()
    from autotrack.io.frames import open_frames
    from autotrack.localization.scene import load_scene
    from autotrack.params import preset
    from autotrack.pipeline import localize_sequence

    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as folder:
        sequence = render_multi_sequence(Path(folder), args.frames)
        scene = load_scene(sequence / "scene.json")
        boxes = json.loads((sequence / "boxes.json").read_text())
        params = preset("autotrack")
        with open_frames(sequence) as source:  # warm-up: kernels loaded, files cached
            first = [source.read(index) for index in range(3)]
            list(localize_sequence(first, scene, boxes, params))
        profile = cProfile.Profile(time.thread_time)
        with open_frames(sequence) as source:
            profile.enable()
            frames = len(list(localize_sequence(source, scene, boxes, params, threads=1)))
            profile.disable()
    stats = pstats.Stats(profile)
    print(f"{frames} frames, four targets + pose, one thread; CPU ms per frame, profiled:")
    for label, file_name, function in PARTS:
        print(f"  {cumulative(stats, file_name, function) / frames * 1e3:7.2f}  {label}")
    stats.sort_stats("tottime").print_stats(args.top)
    return 0


if __name__ == "__main__":
    sys.exit(main())
