"""Peak memory over a long run: 3,000 frames with four targets, in `localize`'s way and the app's.

Runs a generated drifting-texture sequence (`autotrack.synthetic.drift`, 160x120, the default
tracker) through one of two drivers and prints the process's RSS every 250 frames, its peak,
its growth after the first map windows (in all and per 1,000 frames), and (app) after the tab
is closed:

- `localize`: the pipeline as `autotrack localize` / `track` drive it (`Pipeline(map_window=0)`,
  every frame's outcome kept for the report in an `OutcomeLog`);
- `app`: the app's per-tab controller (`TabController`) stepping frame by frame with the
  session recorded, a display snapshot every 10 frames, then the tab closed.

`--keep-all-maps` keeps every map as the code before the map window did (the pipeline's window
set past the sequence's end, and `localize`'s outcomes kept whole): the "before" figures.
Each measurement runs in a fresh process:

    python benchmarks/memory.py localize [--keep-all-maps] [--frames 3000]
    python benchmarks/memory.py app [--keep-all-maps] [--frames 3000]

`poses` prints the bytes kept per frame on the pose side (poses, solver inputs, refined
points, the report's log), traced on the embedded demo: `python benchmarks/memory.py poses`.
`--trace` also lists, with tracemalloc, the allocation sites that grew after the first windows
(what is still kept per frame).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import tracemalloc
from pathlib import Path

import cv2

from autotrack.params import preset
from autotrack.pipeline import FrameOutcome, Pipeline
from autotrack.pipeline.outcomes import OutcomeLog
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

    def __init__(self, trace: bool = False) -> None:
        self.rows: list[tuple[int, float]] = []
        self.started = time.process_time()
        self.traced = Traced(trace)

    def take(self, frame_index: int) -> None:
        self.traced.take(frame_index)
        self.rows.append((frame_index, rss_mb()))
        print(f"  frame {frame_index:5d}: RSS {self.rows[-1][1]:7.1f} MB", flush=True)

    def report(self) -> None:
        """Peak RSS, and the growth from the first sample at or after SETTLED to the last (in
        all and per 1,000 frames)."""
        peak = max(rss for _, rss in self.rows)
        frame, settled = next((f, rss) for f, rss in self.rows if f >= SETTLED)
        growth = self.rows[-1][1] - settled
        last = self.rows[-1][0]
        rate = 1000 * growth / max(last - frame, 1)
        print(f"peak RSS {peak:.1f} MB; growth from frame {frame} to {last}: {growth:+.1f} MB")
        print(f"growth per 1,000 frames: {rate:+.2f} MB")
        print(f"CPU time {time.process_time() - self.started:.0f} s")
        self.traced.report(last - frame)


class Traced:
    """With `--trace`: tracemalloc's allocation sites that grew from SETTLED to the end."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.settled: tracemalloc.Snapshot | None = None
        if enabled:
            tracemalloc.start(8)

    def take(self, frame_index: int) -> None:
        if self.enabled and self.settled is None and frame_index >= SETTLED:
            self.settled = tracemalloc.take_snapshot()

    def report(self, frames: int, top: int = 12) -> None:
        if not self.enabled or self.settled is None:
            return
        grown = tracemalloc.take_snapshot().compare_to(self.settled, "traceback")
        total = sum(stat.size_diff for stat in grown)
        print(f"traced growth after frame {SETTLED}: {total / 1e3:+.1f} kB over {frames} frames")
        for stat in grown[:top]:
            where = " <- ".join(
                f"{Path(f.filename).name}:{f.lineno}" for f in list(stat.traceback)[::-1][:4]
            )
            print(f"  {stat.size_diff / 1e3:+9.1f} kB {stat.count_diff:+7d} blocks  {where}")


def run_localize(settings: DriftSettings, keep_all: bool, trace: bool) -> None:
    frames = DriftingTexture(settings)
    samples = Samples(trace)
    samples.take(0)
    window = settings.frames if keep_all else 0
    kept: list[FrameOutcome] = []
    log = OutcomeLog(())  # what `autotrack localize` keeps (the drift's targets are no landmarks)
    with Pipeline(frames, preset("autotrack"), map_window=window) as pipeline:
        for box in frames.boxes(TARGETS):
            pipeline.add_target(0, box, None)
        for outcome in pipeline.run():
            if keep_all:
                kept.append(outcome)
            else:
                log.append(outcome)
            if outcome.frame_index % EVERY == 0 and outcome.frame_index:
                samples.take(outcome.frame_index)
        samples.take(settings.frames - 1)
    samples.report()


def run_app(settings: DriftSettings, keep_all: bool, trace: bool) -> None:
    from autotrack_studio.config import AppConfig
    from autotrack_studio.controller import TabController
    from autotrack_studio.memory import release_freed_memory
    from autotrack_studio.recordings import RecordingRegistry

    source = DriftingTexture(settings)
    with tempfile.TemporaryDirectory() as folder:
        images = Path(folder) / "drift"
        images.mkdir()
        for index in range(len(source)):
            cv2.imwrite(str(images / f"{index + 1:05d}.jpg"), source.read_bgr(index))
        config = AppConfig(sessions_dir=Path(folder) / "sessions", tracker_threads=1)
        controller = TabController(config, (Path(folder),), RecordingRegistry(), 1)
        samples = Samples(trace)
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


def run_poses(first: int = 20) -> None:
    """Bytes kept per frame on the pose side: `localize` on the embedded demo (scene, four
    landmarks, refinement and re-acquisition on), traced from frame `first` to the end."""
    import json

    from autotrack.io.frames import open_frames
    from autotrack.localization.reacquire import ReacquireParams
    from autotrack.localization.refine import RefineParams
    from autotrack.localization.scene import load_scene
    from autotrack.pipeline import localize_sequence

    demo = Path(__file__).resolve().parents[1] / "static" / "demo"
    scene = load_scene(demo / "scene.json")
    boxes = json.loads((demo / "boxes.json").read_text())
    log = OutcomeLog(scene.landmark_ids)
    tracemalloc.start(8)
    with open_frames(demo / "img") as frames:
        options = {"refine_params": RefineParams(), "reacquire_params": ReacquireParams()}
        run = localize_sequence(frames, scene, boxes, preset("autotrack"), map_window=0, **options)
        last = len(frames) - 1
        for outcome in run:  # the last snapshot before the run ends and frees its trackers
            if outcome.frame_index == first:
                settled = tracemalloc.take_snapshot()
            log.append(outcome)
            if outcome.frame_index == last:
                grown = tracemalloc.take_snapshot().compare_to(settled, "traceback")
    frames_traced = last - first
    total = sum(stat.size_diff for stat in grown)
    print(f"kept per frame, frames {first} to {last}: {total / frames_traced:.0f} B")
    for stat in grown[:12]:
        where = " <- ".join(
            f"{Path(f.filename).name}:{f.lineno}" for f in list(stat.traceback)[::-1][:4]
        )
        print(f"  {stat.size_diff / frames_traced:7.0f} B/frame  {where}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("driver", choices=("localize", "app", "poses"))
    parser.add_argument("--keep-all-maps", action="store_true", help="the 'before' figures")
    parser.add_argument("--frames", type=int, default=3000)
    parser.add_argument(
        "--trace",
        action="store_true",
        help="list the allocation sites that grew after the first windows (tracemalloc; "
        "its own bookkeeping inflates the RSS figures)",
    )
    args = parser.parse_args()
    if args.driver == "poses":
        run_poses()
        return
    settings = DriftSettings(frames=args.frames)
    label = "every map kept" if args.keep_all_maps else "map window"
    print(f"{args.driver}: {args.frames} frames x {TARGETS} targets, {label}")
    if args.driver == "localize":
        run_localize(settings, args.keep_all_maps, args.trace)
    else:
        run_app(settings, args.keep_all_maps, args.trace)


if __name__ == "__main__":
    main()
