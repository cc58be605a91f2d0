"""Fidelity to the authors' release: our AutoTrack against the release's boxes on ../shared/data.

Prints, per sequence, precision@20 and success AUC against the ground truth for our tracker,
the release run under Octave and (UAV sequences) the authors' own outputs, plus the mean and
median per-frame IoU between our boxes and the release's (Octave). A sequence without an Octave
reference (added to the dev set after the Octave run: DragonBaby, ball1, ...) is scored against
its ground truth only and marked "no reference".

The means at the bottom say which set they average: all sequences (ours only), the sequences
with an Octave reference (ours vs the release: the fidelity figure of issue 2), and the
sequences with the authors' own outputs (ours vs the authors').

    python benchmarks/fidelity.py --jobs 2 --color-names ../shared/data/color_names/cn_norm_32768x10.npy
    python benchmarks/fidelity.py --preset strcf --jobs 2
    python benchmarks/fidelity.py --backend reference --jobs 2   # the plain numpy tracker
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from autotrack import AutoTrack, preset
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.evaluation.metrics import overlaps, score_sequence
from autotrack.io.frames import read_image
from autotrack.io.otb_boxes import read_boxes, write_boxes

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
OCTAVE = ("reference", "autotrack_release_octave")
OFFICIAL = ("reference", "autotrack_official")


def track_sequence(
    job: tuple[str, str, str, str | None, str],
) -> tuple[str, str, np.ndarray, float]:
    """(dataset, folder, preset, colour table, backend) -> (dataset, name, 0-based boxes, fps)."""
    dataset, folder, preset_name, colour_table, backend = job
    sequence = load_otb_sequence(Path(folder))[0]
    tracker = AutoTrack(replace(preset(preset_name, colour_table), backend=backend))
    boxes = np.zeros((len(sequence.frame_paths), 4))
    elapsed = 0.0
    for index, path in enumerate(sequence.frame_paths):
        frame = read_image(path, index)
        start = time.perf_counter()
        result = tracker.init(frame, sequence.init_box) if index == 0 else tracker.update(frame)
        elapsed += time.perf_counter() - start
        boxes[index] = result.box
    return dataset, sequence.name, boxes, len(boxes) / elapsed


def sequence_jobs(
    shared: Path,
    preset_name: str,
    colour_table: str | None,
    wanted: set[str] | None = None,
    backend: str = "fast",
) -> list[tuple[str, str, str, str | None, str]]:
    """One job per sequence folder (holding a ground truth) under shared/sequences/<dataset>/."""
    jobs = []
    for dataset_dir in sorted((shared / "sequences").iterdir()):
        if not dataset_dir.is_dir():
            continue
        for folder in sorted(dataset_dir.iterdir()):
            if (folder / "groundtruth_rect.txt").is_file() and (
                not wanted or folder.name in wanted
            ):
                jobs.append((dataset_dir.name, str(folder), preset_name, colour_table, backend))
    return jobs


def track_all(jobs: list, processes: int = 1) -> list[tuple[str, str, np.ndarray, float]]:
    """`track_sequence` over the jobs, in `processes` worker processes (in order)."""
    if processes <= 1:
        return [track_sequence(job) for job in jobs]
    with ProcessPoolExecutor(max_workers=processes) as pool:
        return list(pool.map(track_sequence, jobs))


def scores(boxes: np.ndarray, ground_truth: np.ndarray) -> tuple[float, float]:
    """(P@20, AUC) against the ground truth; NaN ground-truth rows are skipped."""
    score = score_sequence("", boxes, ground_truth)
    return score.precision, score.auc


@dataclass(frozen=True)
class SequenceFidelity:
    """One sequence: our scores, the references' scores where they exist, IoU with the release."""

    dataset: str
    name: str
    ours: tuple[float, float]
    octave: tuple[float, float] | None
    official: tuple[float, float] | None
    iou_octave: np.ndarray | None
    """Per-frame IoU between our boxes and the Octave reference's (None without a reference)."""
    fps: float


def _reference(shared: Path, kind: tuple[str, str], dataset: str, name: str, frames: int):
    path = shared.joinpath(*kind, dataset, f"{name}.txt")
    if not path.is_file():
        return None
    boxes = read_boxes(path)
    if len(boxes) != frames:
        raise ValueError(f"{path}: {len(boxes)} boxes for a {frames}-frame sequence")
    return boxes


def compare(
    shared: Path, dataset: str, name: str, boxes: np.ndarray, fps: float = float("nan")
) -> SequenceFidelity:
    """Score our boxes of one sequence against its ground truth and the references."""
    gt = read_boxes(shared / "sequences" / dataset / name / "groundtruth_rect.txt")
    octave = _reference(shared, OCTAVE, dataset, name, len(gt))
    official = _reference(shared, OFFICIAL, dataset, name, len(gt))
    return SequenceFidelity(
        dataset=dataset,
        name=name,
        ours=scores(boxes, gt),
        octave=None if octave is None else scores(octave, gt),
        official=None if official is None else scores(official, gt),
        iou_octave=None if octave is None else overlaps(boxes, octave),
        fps=fps,
    )


@dataclass(frozen=True)
class FidelityMeans:
    """Means over sequences (each weighted equally), with the set each one averages."""

    all_count: int
    ours_all: tuple[float, float]
    """Ours against the ground truth, every sequence."""
    octave_count: int
    ours_octave_set: tuple[float, float]
    """Ours, over the sequences with an Octave reference."""
    octave: tuple[float, float]
    """The release under Octave, same sequences."""
    mean_iou_octave: float
    """Mean over those sequences of the mean per-frame IoU between our boxes and the release's."""
    official_count: int
    ours_official_set: tuple[float, float]
    official: tuple[float, float]


def _mean(pairs: list[tuple[float, float]]) -> tuple[float, float]:
    if not pairs:
        return (float("nan"), float("nan"))
    values = np.mean(np.array(pairs, dtype=np.float64), axis=0)
    return (float(values[0]), float(values[1]))


def means(rows: list[SequenceFidelity]) -> FidelityMeans:
    """The means of the table's bottom lines."""
    with_octave = [row for row in rows if row.octave is not None]
    with_official = [row for row in rows if row.official is not None]
    return FidelityMeans(
        all_count=len(rows),
        ours_all=_mean([row.ours for row in rows]),
        octave_count=len(with_octave),
        ours_octave_set=_mean([row.ours for row in with_octave]),
        octave=_mean([row.octave for row in with_octave]),
        mean_iou_octave=float(np.mean([np.nanmean(row.iou_octave) for row in with_octave]))
        if with_octave
        else float("nan"),
        official_count=len(with_official),
        ours_official_set=_mean([row.ours for row in with_official]),
        official=_mean([row.official for row in with_official]),
    )


def _pair(values: tuple[float, float] | None) -> str:
    return "no reference" if values is None else f"{values[0]:.3f}/{values[1]:.3f}"


def print_table(rows: list[SequenceFidelity]) -> FidelityMeans:
    """Per-sequence lines, then the means with the set each averages."""
    print(
        f"{'sequence':<14}{'ours P/AUC':>13}{'octave P/AUC':>15}{'official P/AUC':>16}"
        f"{'IoU~oct mean':>13}{'median':>8}{'fps':>7}"
    )
    for row in rows:
        if row.iou_octave is None:
            iou_text = f"{'-':>13}{'-':>8}"
        else:
            iou_text = f"{np.nanmean(row.iou_octave):>13.3f}{np.nanmedian(row.iou_octave):>8.3f}"
        official = "-" if row.official is None else _pair(row.official)
        print(
            f"{row.name:<14}{_pair(row.ours):>13}{_pair(row.octave):>15}{official:>16}"
            f"{iou_text}{row.fps:>7.1f}"
        )
    m = means(rows)
    print(f"mean of all {m.all_count} (vs ground truth): ours {_pair(m.ours_all)}")
    if m.octave_count:
        print(
            f"mean of the {m.octave_count} with an Octave reference: ours {_pair(m.ours_octave_set)}"
            f"  octave {_pair(m.octave)}  mean per-frame IoU ours~octave {m.mean_iou_octave:.3f}"
        )
    if m.official_count:
        print(
            f"mean of the {m.official_count} with the authors' outputs: ours "
            f"{_pair(m.ours_official_set)}  official {_pair(m.official)}"
        )
    return m


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="autotrack")
    parser.add_argument("--backend", choices=("fast", "reference"), default="fast")
    parser.add_argument("--color-names", default=None, help="published Color Names table (.npy)")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--sequences", default="", help="comma-separated subset")
    parser.add_argument("--shared", default=str(SHARED), help="shared data folder")
    parser.add_argument("--save", default=None, help="folder to write our boxes (1-based)")
    args = parser.parse_args()

    shared = Path(args.shared)
    wanted = {s for s in args.sequences.split(",") if s}
    jobs = sequence_jobs(shared, args.preset, args.color_names, wanted, args.backend)
    outputs = track_all(jobs, args.jobs)
    rows = [compare(shared, dataset, name, boxes, fps) for dataset, name, boxes, fps in outputs]
    print_table(rows)
    if args.save:
        for dataset, name, boxes, _ in outputs:
            out = Path(args.save) / dataset
            out.mkdir(parents=True, exist_ok=True)
            write_boxes(out / f"{name}.txt", boxes)


if __name__ == "__main__":
    main()
