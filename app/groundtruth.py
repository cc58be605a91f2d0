"""A benchmark sequence's ground truth in the app: the boxes, and the live scores of the target
started from it, with the library's metrics (the numbers `autotrack track` prints for the same
frames). No viser here."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from autotrack.evaluation.datasets import GROUND_TRUTH_FILE
from autotrack.evaluation.metrics import center_errors, overlaps, score_sequence
from autotrack.io.otb_boxes import read_boxes
from autotrack.pipeline import TrackedTarget


def load_truth(sequence: Path, frame_count: int) -> np.ndarray | None:
    """The sequence folder's groundtruth_rect.txt as 0-based (frame_count, 4) boxes (NaN rows
    past its end), or None without one."""
    path = sequence / GROUND_TRUTH_FILE
    if not (sequence.is_dir() and path.is_file()):
        return None
    boxes = read_boxes(path)[:frame_count]
    padded = np.full((frame_count, 4), np.nan)
    padded[: len(boxes)] = boxes
    return padded


@dataclass(frozen=True)
class TruthView:
    """What the app shows about the ground truth on one frame."""

    box: tuple[float, float, float, float] | None
    """The ground-truth box on this frame (None: none, or the target is invisible)."""
    target_id: str | None
    """The target scored against it (None: no target yet)."""
    errors: np.ndarray
    """Centre error (px) per frame the target was tracked on, NaN elsewhere."""
    ious: np.ndarray
    """Overlap (IoU) per frame the target was tracked on, NaN elsewhere."""
    frames: tuple[int, int] | None
    """First and last frame scored (the target's first box to its last result)."""
    precision: float
    """P@20: fraction of the scored frames with centre error <= 20 px (NaN: none)."""
    auc: float
    """Area under the success curve over the scored frames (NaN: none)."""


def truth_view(truth: np.ndarray, frame_index: int, target: TrackedTarget | None) -> TruthView:
    """The ground truth at `frame_index` and the scores of `target` over the frames from its
    first box to its last result (as `autotrack track` scores a run from its first frame)."""
    count = len(truth)
    row = truth[frame_index]
    box = tuple(float(v) for v in row) if np.isfinite(row).all() and row[2] > 0 else None
    errors, ious = np.full(count, np.nan), np.full(count, np.nan)
    if target is None or not target.results:
        return TruthView(box, None, errors, ious, None, np.nan, np.nan)
    first, last = target.results.first_frame, target.results.last_frame
    pred = np.full((last - first + 1, 4), np.nan)
    pred[target.results.frames - first] = target.results.boxes
    gt = truth[first : last + 1]
    errors[first : last + 1] = center_errors(pred, gt)
    ious[first : last + 1] = overlaps(pred, gt)
    score = score_sequence(target.id, pred, gt)
    return TruthView(box, target.id, errors, ious, (first, last), score.precision, score.auc)
