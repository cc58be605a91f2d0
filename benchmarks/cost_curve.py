"""Cost curve: per-frame time and peak memory against target size, image size, targets, threads.

Each point runs in a fresh process (so its peak memory is its own) on synthetic frames: a
smoothed-noise texture that slides by (1, 2) px a frame, AutoTrack's `autotrack` preset with our
default colour feature, boxes of the given side spread over the image. Timed: the trackers'
update calls only (each frame is cut from the texture before the clock starts), the median over
the updates after the first 5 (which include loading the compiled kernels). For the image-size
points the time to decode one JPEG of that size (cv2.imdecode + BGR->RGB) is given beside it:
that is the only per-frame cost that should grow with the image.

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


class _SlidingTexture:
    """Frames cut from one smoothed-noise texture, sliding by (1, 2) px a frame; each frame is
    copied out when asked for (outside the timed calls), so only the texture stays in memory."""

    def __init__(self, width: int, height: int, count: int) -> None:
        import cv2

        rng = np.random.default_rng(0)
        texture = rng.integers(0, 256, (height + count + 2, width + 2 * count + 2, 3), np.uint8)
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
    """Runs in the child process: mean ms per frame of the update calls, peak RSS in MB."""
    import cv2

    from autotrack.params import preset
    from autotrack.tracker.multi import MultiTracker

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
        cv2.cvtColor(cv2.imdecode(encoded, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
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


def tables(frames: int) -> str:
    lines = []

    def table(title, header, rows):
        lines.extend(["", title, "", header, "|" + "---|" * (header.count("|") - 1)])
        lines.extend(rows)

    rows = []
    for side in (24, 40, 60, 90, 130, 200, 300):
        r = run_point(width=1280, height=720, side=side, targets=1, threads=1, frames=frames)
        rows.append(
            f"| {side} x {side} | {r['search_side']:.0f} | {r['ms_per_frame']:.2f} "
            f"| {1e3 / r['ms_per_frame']:.0f} | {r['peak_mb']:.0f} |"
        )
        print(rows[-1], flush=True)
    table(
        "Target size (one target, 1280x720, one thread). The search region is resampled to "
        "150²-200² px whatever its size; what grows with the box is resampling a larger region "
        "and the 33 scale samples.",
        "| box (px) | search region side (px) | ms / frame | fps | peak MB |",
        rows,
    )
    rows = []
    for width, height in ((640, 360), (1280, 720), (1920, 1080), (3840, 2160)):
        r = run_point(width=width, height=height, side=60, targets=1, threads=1, frames=frames)
        rows.append(
            f"| {width}x{height} | {r['ms_per_frame']:.2f} | {r['decode_ms']:.1f} "
            f"| {r['peak_mb']:.0f} | {r['frames_mb']:.0f} |"
        )
        print(rows[-1], flush=True)
    table(
        "Image size (one 60x60 target, one thread). Tracking cost stays flat; decoding grows "
        "with the image.",
        "| image | tracking ms / frame | JPEG decode ms / frame | peak MB | of which the "
        "benchmark's texture and frames (MB) |",
        rows,
    )
    rows = []
    for targets in (1, 2, 4, 8):
        cells = []
        peaks = []
        for threads in (1, 2):
            r = run_point(
                width=1280, height=720, side=60, targets=targets, threads=threads, frames=frames
            )
            cells.append(f"{r['ms_per_frame']:.2f}")
            peaks.append(f"{r['peak_mb']:.0f}")
        rows.append(f"| {targets} | {cells[0]} | {cells[1]} | {peaks[0]} / {peaks[1]} |")
        print(rows[-1], flush=True)
    table(
        "Targets and threads (60x60 boxes, 1280x720, tracking only).",
        "| targets | ms / frame, 1 thread | ms / frame, 2 threads | peak MB (1 / 2 threads) |",
        rows,
    )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--update-doc", action="store_true")
    parser.add_argument("--point", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.point:
        print(json.dumps(measure_point(**json.loads(args.point))))
        return 0
    load = os.getloadavg()
    header = (
        f"Measured with `python benchmarks/cost_curve.py --frames {args.frames}` on "
        f"{os.cpu_count()} cores, load average {load[0]:.1f} at the start (other jobs were "
        "running: compare rows within a table, not with other machines)."
    )
    print(header, flush=True)
    body = header + "\n" + tables(args.frames)
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
