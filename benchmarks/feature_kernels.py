"""Interleaved micro-benchmark of the feature kernels: this checkout against a git revision.

The inputs are captured while this checkout tracks real frames: the first updates of three dev
sequences (Surfing06, boat5 with a large target, grey Dog1) and of the speed benchmark's rendered
1280x720 sequence (four targets). Per kernel and sequence, both versions run on the same inputs,
call by call in alternating order (a busy machine slows both alike); printed: the median and
minimum wall time per call, the median of the per-call ratios, and whether every output is
identical bit for bit. Kernels (through their public functions, so any revision works):
- `fhog`: `fhog.fhog_weighted_into` of the 200 x 200 search patch with the cosine window;
- `batch`: `features.scale_features` of the scale filter's 33 samples with its window;
- `lookup`: `features.colour_table_feature` with the published Color Names table.

python benchmarks/feature_kernels.py integration3 [--rounds 40] [--frames 12]
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


def capture(frames: int) -> dict[str, list[tuple]]:
    """Kernel name -> [(sequence, arguments)], recorded from this checkout's tracking."""
    import autotrack.tracker.features as features
    from autotrack import AutoTrack, preset
    from autotrack.evaluation.datasets import load_otb_sequence
    from autotrack.io.frames import open_frames, read_image
    from autotrack.localization.scene import load_scene
    from autotrack.pipeline import localize_sequence

    calls: dict[str, list[tuple]] = {"fhog": [], "batch": [], "lookup": []}
    where = ["?"]
    originals = (features.fhog_weighted_into, features._lookup_cell_average, features.fhog_batch)

    def fhog_into(image, weights, out, *rest):
        calls["fhog"].append((where[0], (np.array(image), np.array(weights))))
        return originals[0](image, weights, out, *rest)

    def lookup(rgb, table, cell, weights, out):
        calls["lookup"].append((where[0], (np.array(rgb), cell)))
        return originals[1](rgb, table, cell, weights, out)

    def batch(stack, cell_size=4, n_orients=9, clip=0.2, sample_weights=None):
        if len(stack) >= 16 and sample_weights is not None:  # all the scales, not a few
            calls["batch"].append((where[0], (np.array(stack), np.array(sample_weights))))
        return originals[2](stack, cell_size, n_orients, clip, sample_weights)

    features.fhog_weighted_into, features._lookup_cell_average, features.fhog_batch = (
        fhog_into,
        lookup,
        batch,
    )
    try:
        for dataset, name in KERNEL_SEQUENCES:
            where[0] = name
            sequence = load_otb_sequence(SHARED / "sequences" / dataset / name)[0]
            images = [read_image(path) for path in sequence.frame_paths[: frames + 1]]
            tracker = AutoTrack(preset("autotrack", str(COLOUR_TABLE)))
            tracker.init(images[0], sequence.init_box)
            for image in images[1:]:
                tracker.update(image)
        where[0] = "rendered"
        with tempfile.TemporaryDirectory() as folder:
            rendered = render_multi_sequence(Path(folder), frames + 1)
            scene = load_scene(rendered / "scene.json")
            boxes = json.loads((rendered / "boxes.json").read_text())
            with open_frames(rendered) as source:
                list(localize_sequence(source, scene, boxes, preset("autotrack"), threads=1))
    finally:
        features.fhog_weighted_into, features._lookup_cell_average, features.fhog_batch = originals
    return calls


def runner(module, kind: str, table: np.ndarray):
    """One call of `kind` from package `module` (autotrack or the revision's copy)."""
    fhog = importlib.import_module(f"{module}.tracker.fhog")
    features = importlib.import_module(f"{module}.tracker.features")
    if kind == "fhog":

        def run(image, weights):
            out = np.empty((31, *weights.shape), np.float32)
            fhog.fhog_weighted_into(image, weights, out)
            return out

        return run
    if kind == "batch":
        return features.scale_features
    return lambda rgb, cell: features.colour_table_feature(rgb, table, cell)


def compare(kind: str, entries: list[tuple], base, new, rounds: int) -> str:
    """Interleaved timing of one kernel on one sequence's inputs; the printed line."""
    identical = all(
        np.asarray(base(*args)).tobytes() == np.asarray(new(*args)).tobytes() for args in entries
    )
    times: tuple[list[float], list[float]] = ([], [])
    ratios = []
    for index in range(rounds):
        for args in entries:
            spent = [0.0, 0.0]
            for which in (0, 1) if index % 2 == 0 else (1, 0):
                start = time.perf_counter()
                (base, new)[which](*args)
                spent[which] = time.perf_counter() - start
                times[which].append(spent[which])
            ratios.append(spent[0] / spent[1])
    base_ms, new_ms = (np.median(t) * 1e3 for t in times)
    base_min, new_min = (np.min(t) * 1e3 for t in times)
    return (
        f"{base_ms:6.3f} ms (min {base_min:.3f})  this {new_ms:6.3f} ms (min {new_min:.3f})  "
        f"ratio {np.median(ratios):.3f}  {'identical' if identical else 'DIFFERENT'}"
    )


def main() -> int:
    parser = revision_parser(__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=40, help="timed calls per input")
    parser.add_argument("--frames", type=int, default=12, help="updates captured per sequence")
    args = parser.parse_args()
    if not ready_to_compare(args, "frames", "rounds"):
        return 2
    from autotrack.tracker.features import load_colour_table

    table = load_colour_table(COLOUR_TABLE)  # C-contiguous, as the tracker holds it
    calls = capture(args.frames)
    with tempfile.TemporaryDirectory() as folder:
        if not import_revision(args.revision, Path(folder)):
            return 2
        load = os.getloadavg()
        print(f"load average before: {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}")
        for kind, recorded in calls.items():
            base, new = (runner(module, kind, table) for module in (BASE_PACKAGE, "autotrack"))
            for name in dict.fromkeys(where for where, _ in recorded):
                entries = [arguments for where, arguments in recorded if where == name][:12]
                line = compare(kind, entries, base, new, args.rounds)
                shape = "x".join(str(n) for n in entries[0][0].shape)
                print(f"  {kind:<6} {name:<9} {shape:<12} {args.revision} {line}", flush=True)
    load = os.getloadavg()
    print(f"load average after: {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
