"""How much of a target's update holds Python's GIL: why threads do not scale, processes do.

Four AutoTrack targets on the rendered 1280x720 sequence of speed.py (frames decoded
beforehand), one thread. The update's CPU time is measured without a profiler, then under a
CPU-time cProfile, whose per-function times split it into the calls that release the GIL (the
numba kernels, all declared nogil; scipy.fft's pocketfft transforms; einsum) and the rest.
The rest holds the GIL: two threads can overlap at most the first part. The profiler's own
overhead lands in the rest, so the GIL-held share lies between (plain - released) / plain and
(profiled - released) / profiled; both are printed. CPU time, so a busy machine moves it little.

    python benchmarks/gil_share.py [--frames 140]
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

sys.path.insert(0, str(Path(__file__).resolve().parent))

from speed import render_multi_sequence  # noqa: E402  (sets the one-thread environment)

RELEASING = (
    "_kernel",
    "_area_crop",
    "_area_samples",
    "planar_float32",
    "_rgb_gradients",
    "_any_channel_gradients",
    "gradient_histogram",
    "_normalised_cells",
    "_normalised_batch_cells",
    "_lookup_cell_average",
    "_cell_means",
    "training_sums",
    "shifted_spectrum",
    "scaled_sum",
    "apply_gain",
    "pypocketfft",  # scipy.fft's transforms
    "c_einsum",
)
"""Names of the calls that release the GIL (substrings of cProfile's function names)."""
FFTW_CALLS = ("project", "forward")
"""`dcf.SpectrumTransform` methods that are an FFTW execute plus a kernel or two."""


def released_seconds(stats: pstats.Stats) -> dict[str, float]:
    """Own CPU time of each GIL-releasing call in the profile."""
    seconds = {}
    for (filename, _line, name), entry in stats.stats.items():
        fftw = filename.endswith("dcf.py") and name in FFTW_CALLS
        if fftw or any(part in name for part in RELEASING):
            seconds[name] = seconds.get(name, 0.0) + entry[2]
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=140)
    args = parser.parse_args()

    import cv2

    from autotrack.io.frames import open_frames
    from autotrack.params import preset
    from autotrack.tracker.parallel.multi import MultiTracker

    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as folder:
        sequence = render_multi_sequence(Path(folder), args.frames)
        boxes = json.loads((sequence / "boxes.json").read_text())
        with open_frames(sequence) as source:
            frames = [source.read(index) for index in range(len(source))]
    half = len(frames) // 2
    tracker = MultiTracker(preset("autotrack"))
    tracker.init(frames[0], boxes)
    start = time.thread_time()
    for frame in frames[1:half]:
        tracker.update(frame)
    plain = (time.thread_time() - start) / (half - 1)
    profile = cProfile.Profile(time.thread_time)
    profile.enable()
    for frame in frames[half:]:
        tracker.update(frame)
    profile.disable()
    count = len(frames) - half
    stats = pstats.Stats(profile)
    profiled = sum(entry[2] for entry in stats.stats.values()) / count
    released = {k: v / count for k, v in released_seconds(stats).items()}
    total_released = sum(released.values())
    print(
        f"four targets, CPU ms per frame: {plain * 1e3:.1f} without the profiler, "
        f"{profiled * 1e3:.1f} profiled, of which in GIL-releasing calls "
        f"{total_released * 1e3:.1f}:"
    )
    for name, seconds in sorted(released.items(), key=lambda item: -item[1]):
        print(f"  {seconds * 1e3:6.2f}  {name}")
    low = (plain - total_released) / plain
    high = (profiled - total_released) / profiled
    print(f"GIL held: {low:.0%} - {high:.0%} of a target's update")


if __name__ == "__main__":
    main()
