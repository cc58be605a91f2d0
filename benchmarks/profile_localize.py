"""Where a frame of four targets + pose goes: cProfile (CPU time) of `localize_sequence` on one
thread, in one process, over the speed benchmark's rendered 1280x720 sequence, with what
`autotrack localize` turns on by default (sub-pixel refinement and re-acquisition; `--no-refine
--no-reacquire` as on its command line).

Prints the CPU milliseconds per frame of the pipeline's parts (tracking, decoding, refinement,
the pose, re-acquisition, the rest) and the profile's largest entries by their own time. cProfile sees this thread only,
timed by its own CPU clock (`time.thread_time`): the frames `FrameCache` reads ahead are decoded
on another thread, so decoding shows as the first two frames' and the waits for a frame not
ready yet, and the decoder's CPU time is not counted in whatever this thread ran meanwhile (as
it was with the process's clock before round 16).

python benchmarks/profile_localize.py [--frames 300] [--top 30] [--no-refine] [--no-reacquire]
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
    ("sub-pixel refinement", "posing.py", "refine"),
    ("pose (re-acquisition included)", "pipeline.py", "_estimate_pose"),
    ("re-acquisition", "posing.py", "reacquire"),
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
    parser.add_argument("--no-refine", action="store_true", help="box centres, as the CLI's")
    parser.add_argument("--no-reacquire", action="store_true", help="as the CLI's")
    args = parser.parse_args()
    if args.no_refine and not args.no_reacquire:
        parser.error("re-acquisition needs the refiner's templates: add --no-reacquire")
    from autotrack.io.frames import open_frames
    from autotrack.localization.reacquire import ReacquireParams
    from autotrack.localization.refine import RefineParams
    from autotrack.localization.scene import load_scene
    from autotrack.params import preset
    from autotrack.pipeline import localize_sequence

    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as folder:
        sequence = render_multi_sequence(Path(folder), args.frames)
        scene = load_scene(sequence / "scene.json")
        boxes = json.loads((sequence / "boxes.json").read_text())
        params = preset("autotrack")
        options = {
            "refine_params": None if args.no_refine else RefineParams(),
            "reacquire_params": None if args.no_reacquire else ReacquireParams(),
        }
        with open_frames(sequence) as source:  # warm-up: kernels loaded, files cached
            first = [source.read(index) for index in range(3)]
            list(localize_sequence(first, scene, boxes, params, **options))
        import scipy.optimize  # noqa: F401  (the weighted pose refinement's, imported once)

        profile = cProfile.Profile(time.thread_time)
        with open_frames(sequence) as source:
            profile.enable()
            run = localize_sequence(source, scene, boxes, params, threads=1, **options)
            frames = len(list(run))
            profile.disable()
    stats = pstats.Stats(profile)
    switched = (
        f"refinement {'off' if args.no_refine else 'on'}, "
        f"re-acquisition {'off' if args.no_reacquire else 'on'}"
    )
    print(
        f"{frames} frames, four targets + pose ({switched}), one thread; CPU ms per frame, profiled:"
    )
    for label, file_name, function in PARTS:
        print(f"  {cumulative(stats, file_name, function) / frames * 1e3:7.2f}  {label}")
    stats.sort_stats("tottime").print_stats(args.top)
    return 0


if __name__ == "__main__":
    sys.exit(main())
