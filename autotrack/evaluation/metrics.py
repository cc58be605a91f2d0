"""One-pass evaluation (OPE) metrics as pure numpy functions over box arrays.

Conventions follow the OTB toolkit (Wu, Lim, Yang, "Online Object Tracking: A Benchmark",
CVPR 2013, Sec. 4.1) as used by UAV123, DTB70, UAVDT and VisDrone:

- boxes are (x, y, w, h); the centre is (x + w/2, y + h/2);
- overlap is the IoU of continuous boxes [x, x + w] x [y, y + h] with area w * h. The toolkit's
  1-based inclusive-pixel form (right = x + w - 1, intersection + 1) gives the same numbers;
- precision(t) = fraction of frames with centre error <= t pixels, t = 0..50, scored at 20 px;
- success(t) = fraction of frames with IoU > t, t = 0:0.05:1 (21 thresholds); AUC = mean of
  the success curve;
- frames whose ground truth is NaN or has a non-positive size are excluded (UAV123's invisible
  target); a predicted NaN or empty box is a failure (error = inf, IoU = 0);
- averages over sequences weight every sequence equally (mean of per-sequence curves).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

PRECISION_THRESHOLDS = np.arange(0, 51, dtype=np.float64)
"""Centre-error thresholds in pixels (0..50)."""
SUCCESS_THRESHOLDS = np.linspace(0.0, 1.0, 21)
"""Overlap thresholds 0:0.05:1."""
PRECISION_SCORE_THRESHOLD = 20.0
"""The centre error (pixels) at which precision is reported."""


def valid_boxes(boxes: np.ndarray) -> np.ndarray:
    """Mask of rows that are finite boxes with positive width and height."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    return np.isfinite(boxes).all(axis=1) & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)


def _check_pair(pred: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pred = np.asarray(pred, dtype=np.float64).reshape(-1, 4)
    gt = np.asarray(gt, dtype=np.float64).reshape(-1, 4)
    if pred.shape != gt.shape:
        raise ValueError(f"{len(pred)} predicted boxes for {len(gt)} ground-truth boxes")
    return pred, gt


def center_errors(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Per-frame distance (pixels) between box centres; NaN where the ground truth is invalid,
    inf where the prediction is."""
    pred, gt = _check_pair(pred, gt)
    pred_centres = pred[:, :2] + pred[:, 2:] / 2.0
    gt_centres = gt[:, :2] + gt[:, 2:] / 2.0
    with np.errstate(invalid="ignore"):
        errors = np.hypot(*(pred_centres - gt_centres).T)
    errors[~valid_boxes(pred)] = np.inf
    errors[~valid_boxes(gt)] = np.nan
    return errors


def overlaps(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Per-frame IoU of continuous boxes; NaN where the ground truth is invalid, 0 where the
    prediction is."""
    pred, gt = _check_pair(pred, gt)
    with np.errstate(invalid="ignore"):
        left = np.maximum(pred[:, 0], gt[:, 0])
        right = np.minimum(pred[:, 0] + pred[:, 2], gt[:, 0] + gt[:, 2])
        top = np.maximum(pred[:, 1], gt[:, 1])
        bottom = np.minimum(pred[:, 1] + pred[:, 3], gt[:, 1] + gt[:, 3])
        intersection = np.clip(right - left, 0.0, None) * np.clip(bottom - top, 0.0, None)
        union = pred[:, 2] * pred[:, 3] + gt[:, 2] * gt[:, 3] - intersection
        ious = intersection / union
    ious[~valid_boxes(pred)] = 0.0
    ious[~valid_boxes(gt)] = np.nan
    return ious


def precision_curve(
    errors: np.ndarray, thresholds: np.ndarray = PRECISION_THRESHOLDS
) -> np.ndarray:
    """Fraction of scored frames with centre error <= each threshold (NaN frames excluded).

    All NaN when no frame is scored.
    """
    errors = np.asarray(errors, dtype=np.float64)
    scored = errors[~np.isnan(errors)]
    if scored.size == 0:
        return np.full(len(thresholds), np.nan)
    return (scored[:, None] <= np.asarray(thresholds)[None, :]).mean(axis=0)


def success_curve(ious: np.ndarray, thresholds: np.ndarray = SUCCESS_THRESHOLDS) -> np.ndarray:
    """Fraction of scored frames with IoU > each threshold (NaN frames excluded).

    All NaN when no frame is scored.
    """
    ious = np.asarray(ious, dtype=np.float64)
    scored = ious[~np.isnan(ious)]
    if scored.size == 0:
        return np.full(len(thresholds), np.nan)
    return (scored[:, None] > np.asarray(thresholds)[None, :]).mean(axis=0)


def auc(success: np.ndarray) -> float:
    """Area under the success curve, as the toolkits compute it: the curve's mean."""
    return float(np.mean(success))


@dataclass(frozen=True, eq=False)
class SequenceScore:
    """OPE curves and scores of one tracker on one sequence."""

    name: str
    """Sequence name."""
    precision_curve: np.ndarray
    """Precision at PRECISION_THRESHOLDS."""
    success_curve: np.ndarray
    """Success rate at SUCCESS_THRESHOLDS."""
    scored_frames: int
    """Frames with a valid ground-truth box."""
    attributes: frozenset[str] = frozenset()
    """The sequence's attributes (for per-attribute breakdowns)."""
    dataset: str = ""
    """Dataset the sequence belongs to."""

    @property
    def precision(self) -> float:
        """Precision at 20 px."""
        return float(self.precision_curve[int(PRECISION_SCORE_THRESHOLD)])

    @property
    def auc(self) -> float:
        """Area under the success curve."""
        return auc(self.success_curve)


def score_sequence(
    name: str,
    pred: np.ndarray,
    gt: np.ndarray,
    attributes: Iterable[str] = (),
    dataset: str = "",
) -> SequenceScore:
    """Precision and success curves of predicted boxes against the ground truth."""
    ious = overlaps(pred, gt)
    return SequenceScore(
        name=name,
        precision_curve=precision_curve(center_errors(pred, gt)),
        success_curve=success_curve(ious),
        scored_frames=int(np.count_nonzero(~np.isnan(ious))),
        attributes=frozenset(attributes),
        dataset=dataset,
    )


@dataclass(frozen=True, eq=False)
class SummaryScore:
    """Curves averaged over sequences, each sequence weighted equally."""

    sequences: int
    """Number of sequences averaged (those with at least one scored frame)."""
    precision_curve: np.ndarray
    """Mean precision at PRECISION_THRESHOLDS."""
    success_curve: np.ndarray
    """Mean success rate at SUCCESS_THRESHOLDS."""

    @property
    def precision(self) -> float:
        """Mean precision at 20 px."""
        return float(self.precision_curve[int(PRECISION_SCORE_THRESHOLD)])

    @property
    def auc(self) -> float:
        """AUC of the mean success curve (= mean of the per-sequence AUCs)."""
        return auc(self.success_curve)


def summarize(scores: Sequence[SequenceScore]) -> SummaryScore:
    """Average the per-sequence curves; sequences without a scored frame are left out."""
    used = [score for score in scores if score.scored_frames > 0]
    if not used:
        return SummaryScore(
            0,
            np.full(len(PRECISION_THRESHOLDS), np.nan),
            np.full(len(SUCCESS_THRESHOLDS), np.nan),
        )
    return SummaryScore(
        sequences=len(used),
        precision_curve=np.mean([score.precision_curve for score in used], axis=0),
        success_curve=np.mean([score.success_curve for score in used], axis=0),
    )


def summarize_by_attribute(scores: Sequence[SequenceScore]) -> dict[str, SummaryScore]:
    """One summary per attribute over the sequences that have it, sorted by attribute name."""
    names = sorted({name for score in scores for name in score.attributes})
    return {
        name: summarize([score for score in scores if name in score.attributes]) for name in names
    }


def summarize_by_dataset(scores: Sequence[SequenceScore]) -> dict[str, SummaryScore]:
    """One summary per dataset, sorted by dataset name."""
    names = sorted({score.dataset for score in scores})
    return {name: summarize([score for score in scores if score.dataset == name]) for name in names}
