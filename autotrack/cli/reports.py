"""The report `autotrack localize` prints and the files it writes (TUM poses, the per-frame
tracks table, the smoothed trajectory), for sequences and live sources alike."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from autotrack.io.csv_table import write_csv
from autotrack.localization.scene import Scene

if TYPE_CHECKING:
    from autotrack.pipeline.outcomes import OutcomeLog

DEFAULT_FPS = 10.0
"""Frame rate of the timestamps when neither --fps nor the source gives one."""
LARGE_ERROR_CM = 20.0
"""A valid pose further than this from the ground truth is counted as far off."""


def summarise(
    records: OutcomeLog,
    timestamps: np.ndarray,
    scene: Scene,
    out: Path | None,
    tracks: Path | None,
    gt: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
    name: str,
) -> str:
    """Write the requested files and return the text report (`name` labels the Table-3 row)."""
    from autotrack.io.tum import write_tum
    from autotrack.localization.trajectory import format_table3, trajectory_errors

    poses = records.poses
    positions = np.array([pose.position for pose in poses]).reshape(-1, 3)
    quaternions = np.array([pose.quaternion_xyzw() for pose in poses]).reshape(-1, 4)
    valid = sum(pose.valid for pose in poses)
    three = sum(pose.valid and len(pose.used_landmarks) == 3 for pose in poses)
    lines = [
        f"frames: {len(records)}  valid poses: {valid} ({three} from three landmarks)  "
        f"invalid: {len(records) - valid}"
    ]
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        written = write_tum(out, timestamps, positions, quaternions)
        lines.append(f"poses written to {out} ({written} rows, TUM camera-to-world)")
    if tracks is not None:
        tracks.parent.mkdir(parents=True, exist_ok=True)
        write_csv(tracks, _tracks_header(scene), _tracks_rows(records, timestamps, scene))
        lines.append(f"per-frame tracks written to {tracks}")
    if gt is not None:
        gt_times, gt_positions, _ = gt
        errors = trajectory_errors(timestamps, positions, gt_times, gt_positions)
        lines.append(format_table3([(name, errors)]))
        large = int(np.sum(errors.errors_cm > LARGE_ERROR_CM))
        lines.append(f"valid frames more than {LARGE_ERROR_CM:g} cm off: {large}")
    return "\n".join(lines)


def smoothed_report(
    records: OutcomeLog,
    timestamps: np.ndarray,
    path: Path,
    smoother: Any,
    gt: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
) -> str:
    """Write the smoothed trajectory (`smoother`: SmootherParams) to `path` (TUM) and return
    its report lines (with its errors against `gt`)."""
    from autotrack.io.tum import write_tum
    from autotrack.localization.smoothing import samples_from_poses, smooth_poses
    from autotrack.localization.trajectory import trajectory_errors

    samples = list(smooth_poses(samples_from_poses(records.poses), smoother))
    positions = np.array([p.position for p in samples]).reshape(-1, 3)
    quaternions = np.array([p.quaternion_xyzw for p in samples]).reshape(-1, 4)
    path.parent.mkdir(parents=True, exist_ok=True)
    written = write_tum(path, timestamps, positions, quaternions)
    lines = [
        f"smoothed poses written to {path} ({written} rows, latency "
        f"{smoother.lag_frames} frames = {smoother.latency_s:.2f} s)"
    ]
    if gt is not None:
        errors = trajectory_errors(timestamps, positions, gt[0], gt[1])
        lines.append(
            f"smoothed: RMSE {errors.rmse_cm:.2f} cm, max {errors.max_error_cm:.2f} cm over "
            f"{errors.frames} frames"
        )
    return "\n".join(lines)


def _tracks_header(scene: Scene) -> list[str]:
    """Columns of --tracks: pose (NaN when invalid), validity, landmarks used and left out
    (why), reason when invalid, and per landmark its box, peak score, aberrance flag and
    reprojection error; then per landmark the point given to the solver and whether it was
    refined, and the frame's landmark events (out of view, re-acquired)."""
    header = ["frame", "timestamp", "valid", "tx", "ty", "tz", "qx", "qy", "qz", "qw"]
    header += ["rms_px", "position_std_m", "used", "excluded", "reason"]
    for landmark_id in scene.landmark_ids:
        header += [
            f"{landmark_id}_{k}" for k in ("x", "y", "w", "h", "peak", "aberrant", "error_px")
        ]
    # The point given to the solver (refined or box centre) and what happened to the landmark.
    for landmark_id in scene.landmark_ids:
        header += [f"{landmark_id}_{k}" for k in ("u", "v", "refined")]
    header.append("events")
    return header


def _tracks_rows(records: OutcomeLog, timestamps: np.ndarray, scene: Scene) -> Iterator[list[Any]]:
    frame_indices = records.frame_indices
    for row_index, (pose, stamp) in enumerate(zip(records.poses, timestamps, strict=True)):
        row: list[Any] = [int(frame_indices[row_index]), f"{stamp:.6f}", int(pose.valid)]
        row += [f"{v:.6f}" for v in pose.position]
        row += [f"{v:.6f}" for v in pose.quaternion_xyzw()]
        row += [f"{pose.rms_error_px:.3f}", f"{pose.position_std_m:.4f}"]
        excluded = "; ".join(f"{k} {why}" for k, why in pose.excluded_landmarks.items())
        row += [" ".join(pose.used_landmarks), excluded, pose.reason]
        for landmark_id in scene.landmark_ids:
            track = records.track(row_index, landmark_id)
            if track is None:
                row += ["nan"] * 6
            else:
                box, peak, aberrant = track
                row += [f"{v:.2f}" for v in box]
                row += [f"{peak:.4f}", int(aberrant)]
            row.append(f"{pose.reprojection_errors.get(landmark_id, math.nan):.3f}")
        points, refined = records.image_points(row_index), records.refined(row_index)
        for landmark_id in scene.landmark_ids:
            u, v = points.get(landmark_id, (math.nan, math.nan))
            row += [f"{u:.3f}", f"{v:.3f}", int(refined.get(landmark_id, False))]
        row.append("; ".join(f"{k} {what}" for k, what in records.events(row_index).items()))
        yield row
