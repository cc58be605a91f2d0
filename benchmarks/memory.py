"""Peak memory over a long run: 3,000 frames with four targets, in `localize`'s way and the app's.

Runs a generated drifting-texture sequence (`autotrack.synthetic.drift`, 160x120, the default
tracker) through one of two drivers and prints the process's RSS every 250 frames, its peak,
its growth after the first map window, and (app) after the tab is closed:

- `localize`: the pipeline as `autotrack localize` / `track` drive it (every frame's outcome
  kept for the report, maps dropped; `Pipeline(map_window=0)`);
- `app`: the app's per-tab controller (`TabController`) stepping frame by frame with the
  session recorded, a display snapshot every 10 frames, then the tab closed.

`--keep-all-maps` keeps every map as the code before the map window did (the pipeline's window
set past the sequence's end, and `localize`'s outcomes kept whole): the "before" figures.
Each measurement runs in a fresh process:

    python benchmarks/memory.py localize [--keep-all-maps] [--frames 3000]
    python benchmarks/memory.py app [--keep-all-maps] [--frames 3000]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import cv2

from autotrack.params import preset
from autotrack.pipeline import Pipeline
from autotrack.pipeline.pipeline import MAP_WINDOW
from autotrack.synthetic.drift import DriftingTexture, DriftSettings

TARGETS = 4
EVERY = 250
SETTLED = 2 * MAP_WINDOW
"""Growth is measured from here: the app's map windows full and the allocator warm."""


def rss_mb() -> float:
    """Resident set size of this process now (MB)."""
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


class Samples:
    """RSS along the run."""

    def __init__(self) -> None:
        self.rows: list[tuple[int, float]] = []
        self.started = time.process_time()

    def take(self, frame_index: int) -> None:
        self.rows.append((frame_index, rss_mb()))
        print(f"  frame {frame_index:5d}: RSS {self.rows[-1][1]:7.1f} MB", flush=True)

    def report(self) -> None:
        """Peak RSS, and the growth from the first sample at or after SETTLED to the last."""
        peak = max(rss for _, rss in self.rows)
        frame, settled = next((f, rss) for f, rss in self.rows if f >= SETTLED)
        growth = self.rows[-1][1] - settled
        last = self.rows[-1][0]
        print(f"peak RSS {peak:.1f} MB; growth from frame {frame} to {last}: {growth:+.1f} MB")
        print(f"CPU time {time.process_time() - self.started:.0f} s")


def run_localize(settings: DriftSettings, keep_all: bool) -> None:
    frames = DriftingTexture(settings)
    samples = Samples()
    samples.take(0)
    window = settings.frames if keep_all else 0
    records = []
    with Pipeline(frames, preset("autotrack"), map_window=window) as pipeline:
        for box in frames.boxes(TARGETS):
            pipeline.add_target(0, box, None)
        for outcome in pipeline.run():
            records.append(outcome if keep_all else outcome.without_maps())
            if outcome.frame_index % EVERY == 0 and outcome.frame_index:
                samples.take(outcome.frame_index)
        samples.take(settings.frames - 1)
    samples.report()


def run_app(settings: DriftSettings, keep_all: bool) -> None:
    from app.config import AppConfig
    from app.controller import TabController
    from app.memory import release_freed_memory
    from app.recordings import RecordingRegistry

    source = DriftingTexture(settings)
    with tempfile.TemporaryDirectory() as folder:
        images = Path(folder) / "drift"
        images.mkdir()
        for index in range(len(source)):
            cv2.imwrite(str(images / f"{index + 1:05d}.jpg"), source.read_bgr(index))
        config = AppConfig(sessions_dir=Path(folder) / "sessions", tracker_threads=1)
        controller = TabController(config, (Path(folder),), RecordingRegistry(), 1)
        samples = Samples()
        samples.take(0)
        controller.open(images, None)
        if keep_all:
            controller.require_run().map_window = settings.frames
        for box in source.boxes(TARGETS):
            controller.place_box(box)
        for frame_index in range(1, settings.frames):
            controller.step(1)
            if frame_index % 10 == 0:
                controller.snapshot()
            if frame_index % EVERY == 0:
                samples.take(frame_index)
        samples.take(settings.frames - 1)
        samples.report()
        before = rss_mb()
        controller.close()
        release_freed_memory()
        print(f"tab closed: RSS {before:.1f} -> {rss_mb():.1f} MB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("driver", choices=("localize", "app"))
    parser.add_argument("--keep-all-maps", action="store_true", help="the 'before' figures")
    parser.add_argument("--frames", type=int, default=3000)
    args = parser.parse_args()
    settings = DriftSettings(frames=args.frames)
    label = "every map kept" if args.keep_all_maps else "map window"
    print(f"{args.driver}: {args.frames} frames x {TARGETS} targets, {label}")
    if args.driver == "localize":
        run_localize(settings, args.keep_all_maps)
    else:
        run_app(settings, args.keep_all_maps)


if __name__ == "__main__":
    main()
