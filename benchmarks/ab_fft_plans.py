"""Interleaved A/B of FFTW planning efforts: whole tracker updates on plans of each effort.

Both sides track the four targets of the speed benchmark's rendered 1280x720 sequence in one
process, frame by frame in alternating order, with the same code; only their transforms' FFTW
plans differ (each side's made from wisdom of its own effort, searched here). Prints the thread
CPU time of a frame's four updates on each side and their ratio. The boxes of the two sides
differ at rounding level (another plan rounds differently).

python benchmarks/ab_fft_plans.py [--frames 150] [--efforts FFTW_MEASURE,FFTW_PATIENT]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import cv2

sys.path.insert(0, str(Path(__file__).resolve().parent))
from speed import render_multi_sequence  # noqa: E402  (sets the one-thread environment)


def plans_of_effort(shape: tuple[int, int, int], effort: str) -> tuple:
    """(forward, inverse, second forward) plans of `shape` searched with `effort` alone."""
    from autotrack.tracker.fft_plans import _make_plans, pyfftw

    pyfftw.forget_wisdom()
    return _make_plans(shape, (effort,))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--efforts", default="FFTW_MEASURE,FFTW_PATIENT")
    args = parser.parse_args()
    from autotrack import AutoTrack, preset
    from autotrack.io.frames import open_frames

    efforts = args.efforts.split(",")
    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as folder:
        sequence = render_multi_sequence(Path(folder), args.frames)
        boxes = json.loads((sequence / "boxes.json").read_text())
        with open_frames(sequence) as source:
            frames = [source.read(index) for index in range(args.frames)]
    sides: dict[str, list] = {}
    for effort in efforts:
        sides[effort] = []
        for box in boxes.values():
            target = AutoTrack(preset("autotrack"))
            target.init(frames[0], box)
            sides[effort].append(target)
    for effort, targets in sides.items():
        plans: dict[tuple[int, int, int], tuple] = {}
        for target in targets:  # one thread: targets of one shape may share a set of plans
            transform = target.transform
            shape = transform.input_maps.shape
            if shape not in plans:
                plans[shape] = plans_of_effort(shape, effort)
            transform._forward, transform._inverse, transform._h_forward = plans[shape]
    spent = dict.fromkeys(efforts, 0.0)
    for index, frame in enumerate(frames[1:]):
        for effort in efforts if index % 2 == 0 else efforts[::-1]:
            start = time.thread_time()
            for target in sides[effort]:
                target.update(frame)
            spent[effort] += time.thread_time() - start
    updates = len(frames) - 1
    for effort, seconds in spent.items():
        print(f"{effort:14s} {seconds / updates * 1e3:7.2f} ms CPU for a frame's four updates")
    first, last = efforts[0], efforts[-1]
    print(f"{first} / {last}: {spent[first] / spent[last]:.3f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
