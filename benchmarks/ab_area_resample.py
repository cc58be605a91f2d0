"""Interleaved A/B of the exact area resampling kernels: this checkout against a git revision.

The faithful tracker runs on real inputs (the first frames of the speed benchmark's rendered
1280x720 four-target sequence, one tracker per target, and of the dev sequences Surfing06,
boat5 (a large target) and the grey Dog1) and every 10th update's calls to
`area_resize_crop` (the search patch) and `area_resize_crops` (the 33 scale samples, or the
few crops of another caller) are recorded. Each call is then replayed through the revision's
`area_resample` and this checkout's, alternating which goes first, and the medians of the
per-call thread CPU times are printed per kind of call and input, with whether every output
is identical.

python benchmarks/ab_area_resample.py integration3
python benchmarks/ab_area_resample.py HEAD~1 --frames 40 --repeats 9
"""

from __future__ import annotations

import importlib
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ab_tracker import (  # noqa: E402
    BASE_PACKAGE,
    COLOUR_TABLE,
    KERNEL_SEQUENCES,
    SHARED,
    import_revision,
    ready_to_compare,
    revision_parser,
)
from speed import render_multi_sequence  # noqa: E402


def record_calls(frames: int, folder: Path) -> list[tuple]:
    """(group, function name, arguments) of every 10th update's resampling calls."""
    import autotrack.tracker.sampling as sampling
    from autotrack import AutoTrack
    from autotrack.evaluation.datasets import load_otb_sequence
    from autotrack.io.frames import read_image
    from autotrack.params import preset

    calls: list[tuple] = []
    state = {"group": "", "keep": False}
    originals = {
        name: getattr(sampling, name) for name in ("area_resize_crop", "area_resize_crops")
    }

    def recorder(name):
        def call(*args):
            if state["keep"]:
                kind = "search patch"
                if name == "area_resize_crops":
                    kind = "scale samples" if len(args[1]) > 5 else "other crops"
                calls.append((f"{kind} {state['group']}", name, args))
            return originals[name](*args)

        return call

    runs = []
    rendered = render_multi_sequence(folder, frames + 1)
    images = [read_image(path) for path in sorted((rendered / "img").iterdir())[: frames + 1]]
    for box in json.loads((rendered / "boxes.json").read_text()).values():
        runs.append(("rendered 1280x720", images, box))
    for dataset, name in KERNEL_SEQUENCES:
        sequence = load_otb_sequence(SHARED / "sequences" / dataset / name)[0]
        images = [read_image(path) for path in sequence.frame_paths[: frames + 1]]
        runs.append((name, images, sequence.init_box))
    params = preset("autotrack", str(COLOUR_TABLE))
    for name in originals:
        setattr(sampling, name, recorder(name))
    try:
        for group, images, box in runs:
            state["group"] = group
            tracker = AutoTrack(params)
            tracker.init(images[0], box)
            for index, image in enumerate(images[1:]):
                state["keep"] = index % 10 == 0
                tracker.update(image)
            state["keep"] = False
    finally:
        for name, function in originals.items():
            setattr(sampling, name, function)
    return calls


def compare(calls: list[tuple], modules: tuple, repeats: int) -> None:
    """Print per group the median thread CPU ms per call of both modules and their ratio."""
    groups: dict[str, list[tuple]] = {}
    for group, name, args in calls:
        groups.setdefault(group, []).append((name, args))
    for group, members in groups.items():
        spent: tuple[list[int], list[int]] = ([], [])
        identical = all(
            np.array_equal(getattr(modules[0], name)(*args), getattr(modules[1], name)(*args))
            for name, args in members
        )
        for repeat in range(repeats):
            for index, (name, args) in enumerate(members):
                for which in (0, 1) if (index + repeat) % 2 == 0 else (1, 0):
                    start = time.thread_time_ns()
                    getattr(modules[which], name)(*args)
                    spent[which].append(time.thread_time_ns() - start)
        base, this = (float(np.median(times)) / 1e6 for times in spent)
        print(
            f"  {group:<36} {len(members):3d} calls  base {base:6.3f} ms  this {this:6.3f} ms  "
            f"{base / this:5.2f}x  {'identical' if identical else 'DIFFERENT'}",
            flush=True,
        )


def main() -> int:
    parser = revision_parser(__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40, help="updates per target")
    parser.add_argument("--repeats", type=int, default=7, help="timed replays of each call")
    args = parser.parse_args()
    if not ready_to_compare(args, "frames", "repeats"):
        return 2
    with tempfile.TemporaryDirectory() as folder:
        if not import_revision(args.revision, Path(folder)):
            return 2
        base = importlib.import_module(f"{BASE_PACKAGE}.tracker.area_resample")
        this = importlib.import_module("autotrack.tracker.area_resample")
        calls = record_calls(args.frames, Path(folder) / "sequence")
        load = os.getloadavg()
        print(f"{args.revision} against this checkout; load average before: {load[0]:.1f}")
        compare(calls, (base, this), args.repeats)
    print(f"load average after: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
