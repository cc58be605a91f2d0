"""Trajectory accuracy against ground truth: timestamp association and the paper's Table 3."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class TrajectoryErrors:
    """Position errors of an estimated trajectory against ground truth (paper Table 3)."""

    mean_abs_cm: tuple[float, float, float]
    """Mean |error| along world x, y, z (cm) over the frames with a pose."""
    rmse_cm: float
    """Root-mean-square 3-D position error (cm): sqrt(mean(|p - p_gt|^2))."""
    paper_rmse_cm: float
    """The figure the paper's Table 3 calls RMSE: the norm of the mean-|error| vector
    sqrt(x^2 + y^2 + z^2) (every row of the table satisfies this); never above rmse_cm."""
    max_error_cm: float
    """Largest 3-D position error (cm)."""
    frames: int
    """Ground-truth frames with an estimated pose."""
    missing_frames: int
    """Ground-truth frames with no (valid) estimate at the same timestamp."""
    errors_cm: np.ndarray = field(repr=False, compare=False)
    """Per associated frame 3-D error (cm)."""


def associate(
    timestamps_a: np.ndarray, timestamps_b: np.ndarray, max_difference_s: float = 0.01
) -> tuple[np.ndarray, np.ndarray]:
    """Indices (ia, ib) pairing each stamp of `b` with the nearest stamp of `a` within tolerance."""
    a = np.asarray(timestamps_a, dtype=np.float64)
    b = np.asarray(timestamps_b, dtype=np.float64)
    if len(a) == 0 or len(b) == 0:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    order = np.argsort(a)
    sorted_a = a[order]
    right = np.clip(np.searchsorted(sorted_a, b), 0, len(a) - 1)
    left = np.clip(right - 1, 0, len(a) - 1)
    nearest = np.where(np.abs(sorted_a[left] - b) <= np.abs(sorted_a[right] - b), left, right)
    matched = np.abs(sorted_a[nearest] - b) <= max_difference_s
    return order[nearest[matched]], np.flatnonzero(matched)


def trajectory_errors(
    timestamps: np.ndarray,
    positions: np.ndarray,
    gt_timestamps: np.ndarray,
    gt_positions: np.ndarray,
    max_difference_s: float = 0.01,
) -> TrajectoryErrors:
    """Table-3 errors of `positions` (metres) against ground truth, matched by timestamp.

    Positions with NaN (invalid frames) count as missing.
    """
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    gt_positions = np.asarray(gt_positions, dtype=np.float64).reshape(-1, 3)
    finite = np.all(np.isfinite(positions), axis=1)
    index_est, index_gt = associate(np.asarray(timestamps)[finite], gt_timestamps, max_difference_s)
    difference = (positions[finite][index_est] - gt_positions[index_gt]) * 100.0
    frames = len(index_gt)
    if frames == 0:
        nan = math.nan
        return TrajectoryErrors((nan, nan, nan), nan, nan, nan, 0, len(gt_timestamps), np.zeros(0))
    mean_abs = np.mean(np.abs(difference), axis=0)
    errors = np.linalg.norm(difference, axis=1)
    return TrajectoryErrors(
        mean_abs_cm=(float(mean_abs[0]), float(mean_abs[1]), float(mean_abs[2])),
        rmse_cm=float(np.sqrt(np.mean(errors**2))),
        paper_rmse_cm=float(np.linalg.norm(mean_abs)),
        max_error_cm=float(errors.max()),
        frames=frames,
        missing_frames=len(gt_timestamps) - frames,
        errors_cm=errors,
    )


def format_table3(rows: Sequence[tuple[str, TrajectoryErrors]]) -> str:
    """The paper's Table 3 layout (x, y, z mean |error|, RMSE in cm, frames) plus our columns.

    Adds the paper's RMSE form, the largest error and the frames without a trusted pose; the
    'Average' row averages the rows as the paper does, 'All frames' pools every frame.
    """
    header = (
        f"{'Dataset':<20}{'x(cm)':>8}{'y(cm)':>8}{'z(cm)':>8}{'RMSE':>8}"
        f"{'paperRMSE':>11}{'max(cm)':>9}{'Frames':>8}{'invalid':>9}"
    )
    lines = [header, "-" * len(header)]

    def line(
        name: str,
        x: float,
        y: float,
        z: float,
        rmse: float,
        paper: float,
        worst: float,
        frames: float,
        missing: float,
    ) -> str:
        return (
            f"{name:<20}{x:>8.2f}{y:>8.2f}{z:>8.2f}{rmse:>8.2f}{paper:>11.2f}{worst:>9.2f}"
            f"{frames:>8.0f}{missing:>9.0f}"
        )

    for name, e in rows:
        lines.append(
            line(
                name,
                *e.mean_abs_cm,
                e.rmse_cm,
                e.paper_rmse_cm,
                e.max_error_cm,
                e.frames,
                e.missing_frames,
            )
        )
    if len(rows) > 1:
        stats = [e for _, e in rows]
        means = np.array([e.mean_abs_cm for e in stats]).mean(axis=0)
        lines.append("-" * len(header))
        lines.append(
            line(
                "Average",
                *means,
                float(np.mean([e.rmse_cm for e in stats])),
                float(np.linalg.norm(means)),
                max(e.max_error_cm for e in stats),
                float(np.mean([e.frames for e in stats])),
                float(np.mean([e.missing_frames for e in stats])),
            )
        )
        pooled = np.concatenate([e.errors_cm for e in stats])
        total_frames = sum(e.frames for e in stats)
        weighted = sum(np.array(e.mean_abs_cm) * e.frames for e in stats) / max(total_frames, 1)
        lines.append(
            line(
                "All frames",
                *weighted,
                float(np.sqrt(np.mean(pooled**2))),
                float(np.linalg.norm(weighted)),
                float(pooled.max()),
                total_frames,
                sum(e.missing_frames for e in stats),
            )
        )
    return "\n".join(lines)
