"""Where a frame's time goes: cProfile of AutoTrack on one sequence, frames decoded beforehand.

python benchmarks/profile_tracker.py ../shared/data/sequences/UAV123_10fps/boat5
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time
from pathlib import Path

import cv2

from autotrack import AutoTrack, preset
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.io.frames import read_image


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequence", type=Path, help="an OTB-style sequence folder")
    parser.add_argument("--preset", default="autotrack")
    parser.add_argument("--color-names", default=None)
    parser.add_argument("--rows", type=int, default=20)
    args = parser.parse_args()

    cv2.setNumThreads(1)
    sequence = load_otb_sequence(args.sequence)[0]
    frames = [read_image(path, index) for index, path in enumerate(sequence.frame_paths)]
    tracker = AutoTrack(preset(args.preset, args.color_names))
    tracker.init(frames[0], sequence.init_box)
    tracker.update(frames[1])  # compile and warm up before measuring

    start = time.perf_counter()
    for frame in frames[2:]:
        tracker.update(frame)
    plain = (len(frames) - 2) / (time.perf_counter() - start)

    tracker.init(frames[0], sequence.init_box)
    profile = cProfile.Profile()
    profile.enable()
    for frame in frames[1:]:
        tracker.update(frame)
    profile.disable()
    print(
        f"{sequence.name}: {plain:.1f} fps without the profiler; profile of {len(frames) - 1} updates:"
    )
    pstats.Stats(profile).sort_stats("tottime").print_stats(args.rows)


if __name__ == "__main__":
    main()
