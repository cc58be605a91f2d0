"""Fidelity to the authors' release: our AutoTrack against the release's boxes on ../shared/data.

Prints, per sequence, precision@20 and success AUC against the ground truth for our tracker,
the release run under Octave and (UAV sequences) the authors' own outputs, plus the median
per-frame IoU between our boxes and the release's. Means at the bottom are what issue 2 judges.

    python benchmarks/fidelity.py --color-names ../shared/data/color_names/cn_norm_32768x10.npy
    python benchmarks/fidelity.py --preset strcf --jobs 2
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from autotrack import AutoTrack, preset
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.evaluation.metrics import auc, center_errors, overlaps, precision_at, success_curve
from autotrack.io.frames import read_image
from autotrack.io.otb_boxes import read_boxes, write_boxes

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
UAV_DATASETS = {"UAV123_10fps", "DTB70", "UAVDT"}


def track_sequence(job: tuple[str, str, str, str | None]) -> tuple[str, str, np.ndarray, float]:
    dataset, folder, preset_name, colour_table = job
    sequence = load_otb_sequence(Path(folder))[0]
    tracker = AutoTrack(preset(preset_name, colour_table))
    boxes = np.zeros((len(sequence.frame_paths), 4))
    elapsed = 0.0
    for index, path in enumerate(sequence.frame_paths):
        frame = read_image(path, index)
        start = time.perf_counter()
        if index == 0:
            result = tracker.init(frame, sequence.ground_truth[0])
        else:
            result = tracker.update(frame)
        elapsed += time.perf_counter() - start
        boxes[index] = result.box
    return dataset, sequence.name, boxes, len(boxes) / elapsed


def scores(boxes: np.ndarray, ground_truth: np.ndarray) -> tuple[float, float]:
    return (
        precision_at(center_errors(boxes, ground_truth), 20.0),
        auc(success_curve(overlaps(boxes, ground_truth))),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="autotrack")
    parser.add_argument("--color-names", default=None, help="published Color Names table (.npy)")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--sequences", default="", help="comma-separated subset")
    parser.add_argument("--save", default=None, help="folder to write our boxes (1-based)")
    args = parser.parse_args()

    wanted = {s for s in args.sequences.split(",") if s}
    jobs = []
    for dataset_dir in sorted((SHARED / "sequences").iterdir()):
        for folder in sorted(dataset_dir.iterdir()):
            if folder.is_dir() and (not wanted or folder.name in wanted):
                jobs.append((dataset_dir.name, str(folder), args.preset, args.color_names))
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        outputs = list(pool.map(track_sequence, jobs))

    header = f"{'sequence':<14}{'ours P/AUC':>14}{'octave P/AUC':>15}{'official P/AUC':>16}{'IoU~oct':>9}{'fps':>7}"
    print(header)
    ours_all, octave_all, ours_uav, official_uav = [], [], [], []
    for dataset, name, boxes, fps in outputs:
        gt = read_boxes(SHARED / "sequences" / dataset / name / "groundtruth_rect.txt")
        octave = read_boxes(
            SHARED / "reference" / "autotrack_release_octave" / dataset / f"{name}.txt"
        )
        ours = scores(boxes, gt)
        oct_scores = scores(octave, gt)
        median_iou = float(np.median(overlaps(boxes, octave)))
        ours_all.append(ours)
        octave_all.append(oct_scores)
        official_text = ""
        if dataset in UAV_DATASETS:
            official = read_boxes(
                SHARED / "reference" / "autotrack_official" / dataset / f"{name}.txt"
            )
            off_scores = scores(official, gt)
            ours_uav.append(ours)
            official_uav.append(off_scores)
            official_text = f"{off_scores[0]:.3f}/{off_scores[1]:.3f}"
        print(
            f"{name:<14}{ours[0]:>8.3f}/{ours[1]:.3f}{oct_scores[0]:>9.3f}/{oct_scores[1]:.3f}"
            f"{official_text:>16}{median_iou:>9.3f}{fps:>7.1f}"
        )
        if args.save:
            out = Path(args.save) / dataset
            out.mkdir(parents=True, exist_ok=True)
            write_boxes(out / f"{name}.txt", boxes)
    mean = lambda rows: np.mean(np.array(rows), axis=0)  # noqa: E731
    m_ours, m_oct = mean(ours_all), mean(octave_all)
    print(
        f"mean of {len(ours_all)}: ours {m_ours[0]:.3f}/{m_ours[1]:.3f}  octave {m_oct[0]:.3f}/{m_oct[1]:.3f}"
    )
    if ours_uav:
        m_u, m_off = mean(ours_uav), mean(official_uav)
        print(
            f"mean of {len(ours_uav)} UAV: ours {m_u[0]:.3f}/{m_u[1]:.3f}  official {m_off[0]:.3f}/{m_off[1]:.3f}"
        )


if __name__ == "__main__":
    main()
