"""Interleaved A/B of the tracker: this checkout against a git revision, in one process.

The revision's `autotrack/` is extracted into a temporary folder and imported under another
name, so both versions track the same frames in the same process, one update each in
alternating order, frame by frame: a busy machine slows both alike. Prints, per sequence, the
CPU time (`time.process_time`) per update of each, their ratio, and whether every box and
response map is identical (since round 7 they may differ at the rounding level: measured FFTW
plans; the regression guard of `speed.py` bounds that). Both versions' kernels are compiled
(or loaded) by `tracker.warmup.warm_up` before the timing: the revision's, extracted into a
fresh folder, were otherwise compiled inside its first sequence's timed updates.

python benchmarks/ab_tracker.py integration3
python benchmarks/ab_tracker.py HEAD~1 --frames 100 --preset autotrack+
python benchmarks/ab_tracker.py integration3 --preset autotrack+ --this rotation_step=10

`--this NAME=VALUE,...` changes parameters of this checkout's side only (the cost of a switch
against the revision's preset; the boxes then differ).
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import io
import os
import re
import subprocess
import sys
import tarfile
import tempfile
import time
from dataclasses import fields, replace
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT / ".." / "shared" / "data"
COLOUR_TABLE = SHARED / "color_names" / "cn_norm_32768x10.npy"
SEQUENCES = (
    ("DTB70", "Surfing06"),
    ("UAV123_10fps", "boat5"),
    ("OTB", "Crossing"),
    ("DTB70", "Animal3"),
    ("UAVDT", "S1301"),
    ("DTB70", "Gull1"),
)
"""Small and large targets, grey and colour frames."""
KERNEL_SEQUENCES = (("DTB70", "Surfing06"), ("UAV123_10fps", "boat5"), ("OTB", "Dog1"))
"""The kernel A/Bs' inputs: a small colour target, a large one and a grey sequence."""
BASE_PACKAGE = "autotrack_base"


def unpack_revision(revision: str, folder: Path) -> bool:
    """`autotrack/` of `revision` unpacked into `folder` as it is; False (and a message on
    stderr) when git cannot read the revision."""
    try:
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", revision, "autotrack"],
            check=True,
            capture_output=True,
        ).stdout
    except subprocess.CalledProcessError as error:
        print(f"cannot read {revision}: {error.stderr.decode().strip()}", file=sys.stderr)
        return False
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(folder, filter="data")
    return True


def import_revision(revision: str, folder: Path) -> bool:
    """`autotrack/` of `revision` as the package `autotrack_base` in `folder`, and `folder` on
    the import path; False (and a message on stderr) when git cannot read the revision."""
    if not unpack_revision(revision, folder):
        return False
    package = folder / BASE_PACKAGE
    (folder / "autotrack").rename(package)
    pattern = re.compile(r"\b(from|import) autotrack\b|\"autotrack\.")
    for path in package.rglob("*.py"):
        text = path.read_text()
        renamed = pattern.sub(lambda m: m.group(0).replace("autotrack", BASE_PACKAGE), text)
        path.write_text(renamed)
    sys.path.insert(0, str(folder))
    return True


def ready_to_compare(args: argparse.Namespace, *counts: str) -> bool:
    """True when the published Color Names table is there and every option named in `counts`
    is at least 1; else a message on stderr. Sets OpenCV to one thread, as the tracker runs."""
    if not COLOUR_TABLE.is_file():
        print(f"needs {COLOUR_TABLE}", file=sys.stderr)
        return False
    if any(getattr(args, name) < 1 for name in counts):
        names = " and ".join(f"--{name}" for name in counts)
        print(f"{names} must be at least 1", file=sys.stderr)
        return False
    cv2.setNumThreads(1)
    return True


def revision_parser(description: str) -> argparse.ArgumentParser:
    """An argument parser whose first argument is the git revision to compare with."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("revision", help="git revision to compare with (e.g. integration3)")
    return parser


def parse_overrides(text: str) -> dict:
    """`NAME=VALUE,...` as TrackerParams overrides, each value of its field's type."""
    from autotrack.params import TrackerParams

    types = {
        field.name: type(getattr(TrackerParams(), field.name)) for field in fields(TrackerParams)
    }
    overrides = {}
    for item in filter(None, text.split(",")):
        name, _, value = item.partition("=")
        if name not in types:
            raise ValueError(f"no tracker parameter {name!r}")
        kind = types[name]
        overrides[name] = value in ("1", "true", "True") if kind is bool else kind(value)
    return overrides


def compare(base, new, sequence_dir: Path, preset_name: str, frames: int, overrides: dict) -> tuple:
    """(base ms, new ms, identical, updates) on one sequence."""
    from autotrack.evaluation.datasets import load_otb_sequence
    from autotrack.io.frames import read_image

    sequence = load_otb_sequence(sequence_dir)[0]
    images = [read_image(path) for path in sequence.frame_paths[: frames + 1]]
    params = [module.preset(preset_name, str(COLOUR_TABLE)) for module in (base, new)]
    params[1] = replace(params[1], **overrides)
    trackers = [module.AutoTrack(p) for module, p in zip((base, new), params, strict=True)]
    trackers[0].init(images[0], sequence.init_box)
    trackers[1].init(images[0], sequence.init_box)
    spent = [0.0, 0.0]
    identical = True
    for index, image in enumerate(images[1:]):
        results = [None, None]
        for which in (0, 1) if index % 2 == 0 else (1, 0):
            start = time.process_time()
            results[which] = trackers[which].update(image)
            spent[which] += time.process_time() - start
        identical &= tuple(results[0].box) == tuple(results[1].box) and np.array_equal(
            results[0].response_map, results[1].response_map
        )
    updates = len(images) - 1
    return spent[0] / updates * 1e3, spent[1] / updates * 1e3, identical, updates


def _warmup_module(package: str):
    """The revision's warm-up module: `tracker.parallel.warmup` since issue 37's layout,
    `tracker.warmup` before it."""
    try:
        return importlib.import_module(f"{package}.tracker.parallel.warmup")
    except ModuleNotFoundError:
        return importlib.import_module(f"{package}.tracker.warmup")


def main() -> int:
    parser = revision_parser(__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=150, help="updates per sequence")
    parser.add_argument("--preset", default="autotrack")
    parser.add_argument("--this", default="", help="NAME=VALUE,... for this checkout only")
    args = parser.parse_args()
    try:
        overrides = parse_overrides(args.this)
    except ValueError as error:
        print(f"--this: {error}", file=sys.stderr)
        return 2
    if not ready_to_compare(args):
        return 2
    import autotrack as new

    with tempfile.TemporaryDirectory() as folder:
        if not import_revision(args.revision, Path(folder)):
            return 2
        base = importlib.import_module(BASE_PACKAGE)
        for module in (base, new):  # the revision's kernels compile in its fresh folder: untimed
            warmup = _warmup_module(module.__name__)
            warmup.warm_up(module.preset(args.preset, str(COLOUR_TABLE)))
        load = os.getloadavg()
        print(f"load average before: {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}")
        totals = [0.0, 0.0, 0]
        for dataset, name in SEQUENCES:
            sequence_dir = SHARED / "sequences" / dataset / name
            if not sequence_dir.is_dir():
                continue
            base_ms, new_ms, identical, updates = compare(
                base, new, sequence_dir, args.preset, args.frames, overrides
            )
            print(
                f"  {name:<14} {args.revision} {base_ms:6.3f} ms  this {new_ms:6.3f} ms  "
                f"ratio {base_ms / new_ms:.3f}  {'identical' if identical else 'DIFFERENT'}",
                flush=True,
            )
            totals = [
                totals[0] + base_ms * updates,
                totals[1] + new_ms * updates,
                totals[2] + updates,
            ]
    base_ms, new_ms, updates = totals[0] / totals[2], totals[1] / totals[2], totals[2]
    load = os.getloadavg()
    print(
        f"all {updates} updates: {args.revision} {base_ms:.3f} ms, this {new_ms:.3f} ms per update "
        f"({base_ms / new_ms:.3f}x); load average after: {load[0]:.1f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
