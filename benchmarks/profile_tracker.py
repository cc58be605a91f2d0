"""Where a frame's time goes: cProfile of AutoTrack on one sequence, frames decoded beforehand.

Prints the fps without the profiler, the CPU time of each step of an update (timed by
wrapping the tracker's steps, no profiler), the number of function calls per update (numpy /
scipy, autotrack's own Python functions and compiled kernels, the rest: builtins and the
standard library) and the profile.

python benchmarks/profile_tracker.py ../shared/data/sequences/UAV123_10fps/boat5
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time
from collections import Counter
from pathlib import Path

import cv2

from autotrack import AutoTrack, preset
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.io.frames import read_image
from autotrack.tracker import scale, tracker
from autotrack.tracker.backend.fast import FastBackend
from autotrack.tracker.plus.tracker import AutoTrackPlus

STEPS = (
    (FastBackend, "search_patch", "search patch (sampling)"),
    (FastBackend, "feature_spectrum", "features, window, FFT"),
    (FastBackend, "response", "detection response (eq. 16)"),
    (FastBackend, "peak", "Newton sub-cell peak"),
    (tracker.AutoTrack, "_regularize", "variations, eta, ASR (eqs. 2-4)"),
    (AutoTrackPlus, "_regularize", "autotrack+ variations, eta, ASR (eqs. 2-4)"),
    (AutoTrackPlus, "_disambiguate", "autotrack+ memory: look-alike check"),
    (AutoTrackPlus, "_is_confident", "autotrack+ confidence gate"),
    (scale.ScaleFilter, "detect", "scale filter: detect"),
    (tracker.dcf, "shift_spectrum", "shift of the features"),
    (tracker.AutoTrack, "_train", "ADMM training (eqs. 8-15)"),
    (scale.ScaleFilter, "update", "scale filter: update"),
)
"""(owner, attribute, label) of the steps of `AutoTrack.update` (the fast backend's, and
autotrack+'s own) timed by `step_times`; nested steps count in both."""


def step_times(run) -> dict[str, float]:
    """CPU seconds spent in each of STEPS while `run()` executes (wrappers removed after)."""
    spent: Counter[str] = Counter()
    originals = []
    for owner, name, label in STEPS:
        stored = vars(owner)[name]  # a staticmethod stays one
        originals.append((owner, name, stored))
        function = stored.__func__ if isinstance(stored, staticmethod) else stored

        def timed(*args, _original=function, _label=label, **kwargs):
            start = time.process_time()
            try:
                return _original(*args, **kwargs)
            finally:
                spent[_label] += time.process_time() - start

        setattr(owner, name, staticmethod(timed) if isinstance(stored, staticmethod) else timed)
    try:
        run()
    finally:
        for owner, name, stored in originals:
            setattr(owner, name, stored)
    return dict(spent)


def calls_per_update(stats: pstats.Stats, updates: int) -> dict[str, float]:
    """Function calls per update by where the function lives (cProfile counts every call)."""
    counts = {"numpy / scipy": 0, "autotrack": 0, "builtins and stdlib": 0}
    for (filename, _line, name), entry in stats.stats.items():
        where = f"{filename} {name}"
        if "numpy" in where or "scipy" in where:
            counts["numpy / scipy"] += entry[1]
        elif "autotrack" in filename:
            counts["autotrack"] += entry[1]
        else:
            counts["builtins and stdlib"] += entry[1]
    return {key: value / updates for key, value in counts.items()}


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
    target = AutoTrack(preset(args.preset, args.color_names))
    target.init(frames[0], sequence.init_box)
    target.update(frames[1])  # compile and warm up before measuring

    start = time.perf_counter()
    for frame in frames[2:]:
        target.update(frame)
    plain = (len(frames) - 2) / (time.perf_counter() - start)

    def track() -> None:
        target.init(frames[0], sequence.init_box)
        for frame in frames[1:]:
            target.update(frame)

    update_cpu = time.process_time()
    steps = step_times(track)
    update_cpu = time.process_time() - update_cpu  # init included, and the wrappers' cost

    target.init(frames[0], sequence.init_box)
    profile = cProfile.Profile()
    profile.enable()
    for frame in frames[1:]:
        target.update(frame)
    profile.disable()
    stats = pstats.Stats(profile)
    updates = len(frames) - 1
    counts = calls_per_update(stats, updates)
    print(f"{sequence.name}: {plain:.1f} fps without the profiler")
    print(f"CPU ms per update by step (no profiler; {update_cpu / updates * 1e3:.2f} in all):")
    for label, seconds in steps.items():
        print(f"  {seconds / updates * 1e3:6.3f}  {label}")
    print(
        f"function calls per update: {sum(counts.values()):.0f} ("
        + ", ".join(f"{key} {value:.0f}" for key, value in counts.items())
        + ")"
    )
    print(f"profile of {len(frames) - 1} updates:")
    stats.sort_stats("tottime").print_stats(args.rows)


if __name__ == "__main__":
    main()
