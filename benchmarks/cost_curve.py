"""Cost curve: per-frame time and peak memory against target size, image size, targets, threads.

Each point runs in a fresh process (so its peak memory is its own) on synthetic frames: a
smoothed-noise texture that slides by (1, 2) px a frame, AutoTrack's `autotrack` preset with our
default colour feature, boxes of the given side spread over the image. Timed: the trackers'
update calls only (each frame is cut from the texture before the clock starts), the median over
the updates after the first 5 (which include loading the compiled kernels). For the image-size
points the time to decode one JPEG of that size to RGB (`autotrack.io.jpeg.decode_jpeg`, what
the frame readers use) is given beside it: that is the only per-frame cost that should grow
with the image. Every point runs `--repeats` times (5), in alternating forward and backward
passes over all points, and each time is its fastest run's, the slowest beside it: on a shared
host whose speed changes from one second to the next (by up to 1.6x on the machines of issue
15), a single run, or a median, of a point says as much about the host as about the point.

    python benchmarks/cost_curve.py                 # print the tables
    python benchmarks/cost_curve.py --update-doc    # and rewrite the section of docs/benchmarks.md
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "benchmarks.md"
START, END = "<!-- cost-curve:start -->", "<!-- cost-curve:end -->"
WARM_UP = 5


CENTRE_BLOCK = 512
"""Side (px) of the noise that is the same at every image size around the image's centre."""


class _SlidingTexture:
    """Frames cut from one smoothed-noise texture, sliding by (1, 2) px a frame; each frame is
    copied out when asked for (outside the timed calls), so only the texture stays in memory.

    A target that follows the texture stays at one texture position, its place in the first
    frame. Around the image's centre (the one-target points' box) the noise is one fixed block
    at every image size, so the image-size points track the same content: what they compare
    is the image's size, not what the target happens to look like at that size."""

    def __init__(self, width: int, height: int, count: int) -> None:
        import cv2

        rng = np.random.default_rng(0)
        texture = rng.integers(0, 256, (height + count + 2, width + 2 * count + 2, 3), np.uint8)
        block = np.random.default_rng(1).integers(0, 256, (CENTRE_BLOCK,) * 2 + (3,), np.uint8)
        top, left = height // 2 - CENTRE_BLOCK // 2, width // 2 - CENTRE_BLOCK // 2
        rows = slice(max(top, 0), min(top + CENTRE_BLOCK, texture.shape[0]))
        cols = slice(max(left, 0), min(left + CENTRE_BLOCK, texture.shape[1]))
        texture[rows, cols] = block[
            rows.start - top : rows.stop - top, cols.start - left : cols.stop - left
        ]
        self.texture = cv2.GaussianBlur(texture, (0, 0), 2.0)
        self.width, self.height = width, height

    def frame(self, k: int) -> np.ndarray:
        return np.ascontiguousarray(self.texture[k : k + self.height, 2 * k : 2 * k + self.width])


def _boxes(width: int, height: int, side: float, targets: int) -> dict[str, tuple]:
    """`targets` square boxes of `side` px on a grid over the middle of the image."""
    columns = int(np.ceil(np.sqrt(targets)))
    rows = int(np.ceil(targets / columns))
    boxes = {}
    for index in range(targets):
        row, col = divmod(index, columns)
        cx = width * (col + 1) / (columns + 1)
        cy = height * (row + 1) / (rows + 1)
        boxes[f"t{index}"] = (cx - side / 2, cy - side / 2, side, side)
    return boxes


def measure_point(width: int, height: int, side: float, targets: int, threads: int, frames: int):
    """Runs in the child process: the median ms per frame of the update calls after the
    first WARM_UP, the JPEG decode time, peak RSS in MB."""
    import cv2

    from autotrack.io.jpeg import decode_jpeg
    from autotrack.params import preset
    from autotrack.tracker.parallel.multi import MultiTracker

    cv2.setNumThreads(1)
    source = _SlidingTexture(width, height, frames)
    boxes = _boxes(width, height, side, targets)
    times = []
    with MultiTracker(preset("autotrack"), tuple(boxes), threads=threads) as tracker:
        first = source.frame(0)
        results = tracker.init(first, boxes)
        search_side = results["t0"].search_box[2]
        for k in range(1, frames):
            image = source.frame(k)
            start = time.perf_counter()
            tracker.update(image)
            times.append(time.perf_counter() - start)
    ok, encoded = cv2.imencode(".jpg", cv2.cvtColor(first, cv2.COLOR_RGB2BGR))
    decode = []
    for _ in range(5):
        start = time.perf_counter()
        decode_jpeg(encoded)  # the frame readers' decoder (to RGB)
        decode.append(time.perf_counter() - start)
    return {
        "ms_per_frame": 1e3 * float(np.median(times[WARM_UP:])),
        "decode_ms": 1e3 * float(np.median(decode)),
        "search_side": float(search_side),
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "frames_mb": (source.texture.nbytes + first.nbytes + image.nbytes) / 2**20,
    }


def run_point(**point) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
    done = subprocess.run(
        [sys.executable, __file__, "--point", json.dumps(point)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


TARGET_SIDES = (24, 40, 60, 90, 130, 200, 300)
IMAGE_SIZES = ((640, 360), (1280, 720), (1920, 1080), (3840, 2160))
TARGET_COUNTS = (1, 2, 4, 8)


def _points(frames: int) -> list[tuple]:
    """Every point of the three tables, as a hashable (width, height, side, targets, threads,
    frames) tuple; a point the tables share is measured once."""
    points = [(1280, 720, side, 1, 1, frames) for side in TARGET_SIDES]
    points += [(width, height, 60, 1, 1, frames) for width, height in IMAGE_SIZES]
    points += [(1280, 720, 60, n, threads, frames) for n in TARGET_COUNTS for threads in (1, 2)]
    return list(dict.fromkeys(points))


def measure_all(frames: int, repeats: int) -> dict[tuple, list[dict]]:
    """Each point `repeats` times, in alternating forward and backward passes over all points:
    a drift of the machine's speed during the run (a busy neighbour, a shared host) then falls
    on every point alike instead of on whichever ran during it."""
    points = _points(frames)
    runs: dict[tuple, list[dict]] = {point: [] for point in points}
    keys = ("width", "height", "side", "targets", "threads", "frames")
    for repeat in range(repeats):
        for point in points if repeat % 2 == 0 else points[::-1]:
            runs[point].append(run_point(**dict(zip(keys, point, strict=True))))
            done = sum(len(r) for r in runs.values())
            print(f"  point {done}/{len(points) * repeats}", file=sys.stderr, flush=True)
    return runs


def _ms(results: list[dict]) -> str:
    """The fastest run's ms per frame, with the slowest beside it when there are several."""
    times = [r["ms_per_frame"] for r in results]
    if len(times) == 1:
        return f"{times[0]:.2f}"
    return f"{min(times):.2f} (slowest {max(times):.2f})"


def _fastest(results: list[dict]) -> dict:
    return min(results, key=lambda r: r["ms_per_frame"])


def _median(results: list[dict], key: str) -> float:
    return float(np.median([r[key] for r in results]))


def tables(frames: int, repeats: int = 1) -> str:
    runs = measure_all(frames, repeats)
    lines = []

    def table(title, header, rows):
        lines.extend(["", title, "", header, "|" + "---|" * (header.count("|") - 1)])
        lines.extend(rows)

    rows = []
    for side in TARGET_SIDES:
        r = runs[(1280, 720, side, 1, 1, frames)]
        rows.append(
            f"| {side} x {side} | {_median(r, 'search_side'):.0f} | {_ms(r)} "
            f"| {1e3 / _fastest(r)['ms_per_frame']:.0f} | {_median(r, 'peak_mb'):.0f} |"
        )
    table(
        "Target size (one target, 1280x720, one thread). The search region is resampled to "
        "150²-200² px whatever its size; what grows with the box is resampling a larger region "
        "and the 33 scale samples.",
        "| box (px) | search region side (px) | ms / frame | fps | peak MB |",
        rows,
    )
    rows = []
    for width, height in IMAGE_SIZES:
        r = runs[(width, height, 60, 1, 1, frames)]
        rows.append(
            f"| {width}x{height} | {_ms(r)} | {min(x['decode_ms'] for x in r):.1f} "
            f"| {_median(r, 'peak_mb'):.0f} | {_median(r, 'frames_mb'):.0f} |"
        )
    table(
        "Image size (one 60x60 target, one thread). Tracking cost stays flat; decoding grows "
        "with the image.",
        "| image | tracking ms / frame | JPEG decode ms / frame | peak MB | of which the "
        "benchmark's texture and frames (MB) |",
        rows,
    )
    rows = []
    for targets in TARGET_COUNTS:
        one, two = (runs[(1280, 720, 60, targets, t, frames)] for t in (1, 2))
        rows.append(
            f"| {targets} | {_ms(one)} | {_ms(two)} "
            f"| {_median(one, 'peak_mb'):.0f} / {_median(two, 'peak_mb'):.0f} |"
        )
    table(
        "Targets and threads (60x60 boxes, 1280x720, tracking only).",
        "| targets | ms / frame, 1 thread | ms / frame, 2 threads | peak MB (1 / 2 threads) |",
        rows,
    )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument(
        "--repeats",
        type=int,
        default=5,
        help="runs of every point, interleaved; each time is the fastest run's (slowest beside)",
    )
    parser.add_argument("--update-doc", action="store_true")
    parser.add_argument("--point", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.point:
        print(json.dumps(measure_point(**json.loads(args.point))))
        return 0
    load = os.getloadavg()
    header = (
        f"Measured with `python benchmarks/cost_curve.py --frames {args.frames} --repeats"
        f" {args.repeats}` on {os.cpu_count()} cores, load average {load[0]:.1f} at the start."
        + (
            f" Each time is the fastest of {args.repeats} runs of the point (the slowest in"
            " brackets), in alternating forward and backward passes over all points: compare"
            " rows within a table, not with other machines."
            if args.repeats > 1
            else " One run a point: compare rows within a table, not with other machines."
        )
    )
    print(header, flush=True)
    body = header + "\n" + tables(args.frames, max(args.repeats, 1))
    print(body)
    if args.update_doc:
        text = DOC.read_text()
        if START not in text:
            raise SystemExit(f"{DOC} has no {START} ... {END} section")
        before, rest = text.split(START, 1)
        after = rest.split(END, 1)[1]
        DOC.write_text(f"{before}{START}\n{body}\n{END}{after}")
        print(f"\nupdated {DOC.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
