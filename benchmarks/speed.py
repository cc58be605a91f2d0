"""Speed side by side: AutoTrack, STRCF, autotrack+, OpenCV CSRT and KCF on the dev sequences.

Prints per tracker the median fps over sequences, the frame-weighted fps and the peak memory of
its process (each tracker runs alone in a fresh process, the others waiting), the AutoTrack /
CSRT ratio, the per-frame time of four AutoTrack targets plus the pose step on 1280x720 frames,
and the regression guard: AutoTrack's boxes (published Color Names table) against the
pre-optimisation boxes kept in benchmarks/reference_boxes/ (0.5 px tolerance). Exit status 1
when the guard fails.

    python benchmarks/speed.py                 # everything
    python benchmarks/speed.py --skip-multi    # trackers and guard only
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT / ".." / "shared" / "data"
COLOUR_TABLE = SHARED / "color_names" / "cn_norm_32768x10.npy"
REFERENCE = ROOT / "benchmarks" / "reference_boxes"
TOLERANCE_PX = 0.5


def _single_thread_env() -> None:
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ[name] = "1"


def run_tracker(tracker: str, colour_table: str | None) -> dict:
    """All dev sequences with one tracker, in this (fresh) process."""
    from autotrack.benchmark import run_task
    from autotrack.datasets import load_sequences

    per_sequence = {}
    for sequence in load_sequences(SHARED / "sequences"):
        result = run_task(tracker, sequence, colour_table)
        per_sequence[sequence.name] = (result.frames, result.seconds, result.boxes)
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"sequences": per_sequence, "peak_mb": peak_kib / 1024.0}


def _in_fresh_process(tracker: str, colour_table: str | None) -> dict:
    with ProcessPoolExecutor(max_workers=1, initializer=_single_thread_env) as pool:
        return pool.submit(run_tracker, tracker, colour_table).result()


def multi_target_pose(frames_count: int, threads: int) -> tuple[float, int, float]:
    """Seconds per frame of four AutoTrack targets + the pose step on rendered 1280x720 frames."""
    from autotrack.frames import open_frames
    from autotrack.localize import localize_sequence
    from autotrack.params import preset
    from autotrack.scene import load_scene
    from autotrack.synthetic import render_sequence, sequence_specs

    spec = sequence_specs(1, frames=frames_count, seed=3)[0]
    with tempfile.TemporaryDirectory() as folder:
        out = render_sequence(Path(folder) / spec.name, spec)
        source = open_frames(out)
        frames = [source.read(i) for i in range(len(source))]
        scene = load_scene(out / "scene.json")
        import json

        boxes = json.loads((out / "boxes.json").read_text())
    height, width = frames[0].shape[:2]
    start = time.perf_counter()
    valid = 0
    for record in localize_sequence(frames, scene, boxes, preset("autotrack"), threads=threads):
        valid += bool(record.pose.valid)
    elapsed = time.perf_counter() - start
    return elapsed / len(frames), valid, float(width * 10000 + height)


def guard(boxes_by_sequence: dict[str, np.ndarray]) -> bool:
    """Compare with the kept pre-optimisation boxes; print and return whether the guard passes.

    Frame-by-frame identity within 0.5 px is reported per sequence. The tracker is chaotic under
    float rounding (an FFT library or summation order moves a one-pixel rounding decision, and
    the sequences then wander apart), so the guard fails on what such noise cannot explain:
    mean precision@20 or mean AUC over the twelve sequences moving by more than 0.01 (the spec's
    bound for rounding noise), or a sequence whose boxes differ from its very first frames.
    """
    from autotrack.datasets import read_boxes
    from autotrack.evaluation import score_sequence

    print(
        f"\nregression guard (AutoTrack + published table vs {REFERENCE.name}/, {TOLERANCE_PX} px)"
    )
    ok = True
    ours, kept = [], []
    for name, boxes in sorted(boxes_by_sequence.items()):
        reference_path = next(REFERENCE.glob(f"*/{name}.txt"), None)
        if reference_path is None:
            print(f"  {name:<14} no reference kept")
            ok = False
            continue
        reference = read_boxes(reference_path)
        truth = read_boxes(
            SHARED / "sequences" / reference_path.parent.name / name / "groundtruth_rect.txt"
        )
        deviation = np.max(np.abs(boxes - reference), axis=1)
        bad = np.flatnonzero(deviation > TOLERANCE_PX)
        if bad.size == 0:
            status = "identical"
        else:
            status = f"first differs at frame {bad[0]} ({bad.size} frames > {TOLERANCE_PX} px)"
            ok &= bool(bad[0] >= 5)
        score, kept_score = (
            score_sequence(name, boxes, truth),
            score_sequence(name, reference, truth),
        )
        ours.append((score.precision, score.auc))
        kept.append((kept_score.precision, kept_score.auc))
        print(
            f"  {name:<14} max |d| {deviation.max():7.2f} px  P/AUC {score.precision:.3f}/"
            f"{score.auc:.3f} (kept {kept_score.precision:.3f}/{kept_score.auc:.3f})  {status}"
        )
    mean_ours, mean_kept = np.mean(ours, axis=0), np.mean(kept, axis=0)
    drift = np.abs(mean_ours - mean_kept)
    print(
        f"  mean P/AUC {mean_ours[0]:.3f}/{mean_ours[1]:.3f}, kept {mean_kept[0]:.3f}/"
        f"{mean_kept[1]:.3f}: drift {drift[0]:.3f}/{drift[1]:.3f} (limit 0.010)"
    )
    return ok and bool(np.all(drift <= 0.01))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trackers", default="autotrack,strcf,autotrack+,csrt,kcf")
    parser.add_argument("--skip-multi", action="store_true")
    parser.add_argument("--multi-frames", type=int, default=80)
    parser.add_argument("--multi-threads", type=int, default=2)
    args = parser.parse_args()
    if not SHARED.is_dir():
        print(f"needs {SHARED}", file=sys.stderr)
        return 2

    trackers = [name.strip() for name in args.trackers.split(",") if name.strip()]
    results = {}
    for tracker in trackers:
        table = str(COLOUR_TABLE) if tracker in ("autotrack", "strcf") else None
        results[tracker] = _in_fresh_process(tracker, table)

    print(
        f"{'tracker':<11}{'median fps':>11}{'overall fps':>13}{'peak MB':>9}  (single thread, tracking time only)"
    )
    medians = {}
    for tracker, result in results.items():
        rows = result["sequences"].values()
        fps = [frames / seconds for frames, seconds, _ in rows]
        total_frames = sum(frames for frames, _, _ in rows)
        total_seconds = sum(seconds for _, seconds, _ in rows)
        medians[tracker] = float(np.median(fps))
        print(
            f"{tracker:<11}{medians[tracker]:>11.1f}{total_frames / total_seconds:>13.1f}"
            f"{result['peak_mb']:>9.0f}"
        )
    for name in ("autotrack", "autotrack+"):
        if name in medians and "csrt" in medians:
            print(f"{name} / CSRT median fps: {medians[name] / medians['csrt']:.2f}x")
    print(
        "\nper sequence fps: "
        + ", ".join(
            f"{name} {frames / seconds:.0f}"
            for name, (frames, seconds, _) in results.get("autotrack", {"sequences": {}})[
                "sequences"
            ].items()
        )
    )

    if not args.skip_multi:
        _single_thread_env()
        seconds, valid, _ = multi_target_pose(args.multi_frames, args.multi_threads)
        print(
            f"\nfour targets + pose, 1280x720, {args.multi_threads} threads: "
            f"{seconds * 1e3:.1f} ms/frame = {1 / seconds:.1f} fps ({valid}/{args.multi_frames} valid poses)"
        )

    ok = True
    if "autotrack" in results:
        boxes = {name: b for name, (_, _, b) in results["autotrack"]["sequences"].items()}
        ok = guard(boxes)
        print("guard:", "PASS" if ok else "FAIL: results changed (see above)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
