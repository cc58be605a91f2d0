"""A sequence's ground truth in the app: the target boxes (a benchmark's groundtruth_rect.txt, or
the per-landmark groundtruth/<landmark>.txt a generated sequence such as the demo ships), the
live scores of the targets tracked against them (the library's metrics: the numbers `autotrack
track` prints for the same frames), and the camera poses of a `poses_gt.tum` against which the
estimated poses get a live position and rotation error (ATE, RPE per second). No viser here."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from autotrack.evaluation.datasets import GROUND_TRUTH_FILE
from autotrack.evaluation.metrics import center_errors, overlaps, score_sequence
from autotrack.io.otb_boxes import read_boxes
from autotrack.io.tum import read_tum
from autotrack.pipeline import TrackedTarget
from autotrack.result import PoseEstimate

LANDMARK_TRUTH_FOLDER = "groundtruth"
"""Beside a generated sequence's img/: one `<landmark>.txt` of 0-based x,y,w,h rows per frame."""


def _padded(boxes: np.ndarray, frame_count: int) -> np.ndarray:
    padded = np.full((frame_count, 4), np.nan)
    rows = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)[:frame_count]
    padded[: len(rows)] = rows
    return padded


def load_truth(sequence: Path, frame_count: int) -> np.ndarray | None:
    """The sequence folder's groundtruth_rect.txt as 0-based (frame_count, 4) boxes (NaN rows
    past its end), or None without one."""
    path = sequence / GROUND_TRUTH_FILE
    if not (sequence.is_dir() and path.is_file()):
        return None
    return _padded(read_boxes(path), frame_count)


def load_landmark_truth(
    sequence: Path, frame_count: int, landmark_ids: tuple[str, ...]
) -> dict[str, np.ndarray]:
    """The sequence folder's groundtruth/<landmark>.txt for the scene's landmarks (0-based
    x,y,w,h rows, as `autotrack synth` writes them) as (frame_count, 4) boxes; a file that does
    not read as such rows is left out."""
    folder = sequence / LANDMARK_TRUTH_FOLDER if sequence.is_dir() else None
    truth: dict[str, np.ndarray] = {}
    if folder is None or not folder.is_dir():
        return truth
    for landmark_id in landmark_ids:
        path = folder / f"{landmark_id}.txt"
        if not path.is_file():
            continue
        try:
            rows = np.loadtxt(path, delimiter=",", ndmin=2)
        except ValueError:
            continue
        if rows.shape[1] == 4:
            truth[landmark_id] = _padded(rows, frame_count)
    return truth


@dataclass(frozen=True)
class TruthView:
    """What the app shows about one target's ground truth on one frame."""

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
    label: str = "GT"
    """How the box is labelled on the frame (`GT`, or `GT A` for landmark A's)."""


def truth_view(
    truth: np.ndarray, frame_index: int, target: TrackedTarget | None, label: str = "GT"
) -> TruthView:
    """The ground truth at `frame_index` and the scores of `target` over the frames from its
    first box to its last result (as `autotrack track` scores a run from its first frame)."""
    count = len(truth)
    row = truth[frame_index]
    box = tuple(float(v) for v in row) if np.isfinite(row).all() and row[2] > 0 else None
    errors, ious = np.full(count, np.nan), np.full(count, np.nan)
    if target is None or not target.results:
        return TruthView(box, None, errors, ious, None, np.nan, np.nan, label)
    first, last = target.results.first_frame, target.results.last_frame
    pred = np.full((last - first + 1, 4), np.nan)
    pred[target.results.frames - first] = target.results.boxes
    gt = truth[first : last + 1]
    errors[first : last + 1] = center_errors(pred, gt)
    ious[first : last + 1] = overlaps(pred, gt)
    score = score_sequence(target.id, pred, gt)
    return TruthView(box, target.id, errors, ious, (first, last), score.precision, score.auc, label)


# -- camera poses -------------------------------------------------------------------------------


@dataclass(frozen=True)
class TruthPoses:
    """Ground-truth camera poses (camera-to-world), one row per frame of the sequence that has
    one (NaN elsewhere), matched to frames by timestamp = frame / fps."""

    positions: np.ndarray
    """(frame_count, 3) metres."""
    rotations: np.ndarray
    """(frame_count, 3, 3) camera-to-world rotations."""


def load_truth_poses(
    scene_path: Path | None, frame_count: int, fps: float | None
) -> TruthPoses | None:
    """The `poses_gt.tum` beside a scene file as per-frame poses (frame k at k / fps s, the
    nearest stamp within half a frame; the file's order when the sequence has no rate)."""
    if scene_path is None or not (scene_path.parent / "poses_gt.tum").is_file():
        return None
    stamps, positions, quaternions = read_tum(scene_path.parent / "poses_gt.tum")
    out_positions = np.full((frame_count, 3), np.nan)
    out_rotations = np.full((frame_count, 3, 3), np.nan)
    if fps:
        frame_stamps = np.arange(frame_count) / fps
        nearest = np.abs(frame_stamps[:, None] - stamps[None, :]).argmin(axis=1)
        matched = np.abs(stamps[nearest] - frame_stamps) <= 0.5 / fps
        frames, rows = np.flatnonzero(matched), nearest[matched]
    else:
        frames = rows = np.arange(min(frame_count, len(stamps)))
    out_positions[frames] = positions[rows]
    out_rotations[frames] = Rotation.from_quat(quaternions[rows]).as_matrix()
    return TruthPoses(out_positions, out_rotations)


def rotation_angle_deg(rotation: np.ndarray) -> np.ndarray:
    """Angle (degrees) of rotation matrices (..., 3, 3): arccos((trace - 1) / 2)."""
    trace = np.trace(rotation, axis1=-2, axis2=-1)
    return np.degrees(np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0)))


@dataclass(frozen=True)
class PoseErrors:
    """The estimated poses so far against the ground truth."""

    frames: int
    """Frames with a trusted pose and a ground-truth pose."""
    position_errors_m: np.ndarray
    """Per frame: |p - p_gt| (m), NaN where there is none to compare."""
    rotation_errors_deg: np.ndarray
    """Per frame: the angle of R_gt^T R (degrees), NaN where there is none."""
    ate_m: float
    """Absolute trajectory error: RMS of the position errors (m; no alignment, the poses are
    in the scene's world frame)."""
    ate_deg: float
    """RMS of the rotation errors (degrees)."""
    rpe_m: float
    """Relative pose error over one second (round(fps) frames): RMS of the translation of
    (Q_i^-1 Q_j)^-1 (P_i^-1 P_j), Sturm et al. 2012's RPE (m per second; NaN: no pair)."""
    rpe_deg: float
    """The same relative error's rotation angle, RMS (degrees per second)."""


def _rms(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(finite**2))) if finite.size else math.nan


def pose_errors(
    truth: TruthPoses, poses: Mapping[int, PoseEstimate], fps: float | None
) -> PoseErrors:
    """ATE and RPE per second of the trusted `poses` (by frame) against `truth`."""
    count = len(truth.positions)
    positions = np.full((count, 3), np.nan)
    rotations = np.full((count, 3, 3), np.nan)
    for index, pose in poses.items():
        if pose.valid and 0 <= index < count:
            positions[index], rotations[index] = pose.position, pose.rotation
    position_errors = np.linalg.norm(positions - truth.positions, axis=1)
    relative = np.einsum("nji,njk->nik", truth.rotations, rotations)  # R_gt^T R
    rotation_errors = rotation_angle_deg(relative)
    lag = max(1, round(fps or 1.0))
    rpe_m, rpe_deg = _relative_errors(truth, positions, rotations, lag)
    return PoseErrors(
        frames=int(np.isfinite(position_errors).sum()),
        position_errors_m=position_errors,
        rotation_errors_deg=rotation_errors,
        ate_m=_rms(position_errors),
        ate_deg=_rms(rotation_errors),
        rpe_m=rpe_m,
        rpe_deg=rpe_deg,
    )


def _relative_errors(
    truth: TruthPoses, positions: np.ndarray, rotations: np.ndarray, lag: int
) -> tuple[float, float]:
    """RMS translation (m) and rotation (degrees) of E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j) over the
    frame pairs j = i + lag with both poses (Sturm et al. 2012, eq. 1 with delta = lag)."""
    if len(positions) <= lag:
        return math.nan, math.nan

    def motion(rot: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(R_i^T R_j, R_i^T (p_j - p_i)): pose i's inverse times pose j."""
        first, second = rot[:-lag], rot[lag:]
        step = np.einsum("nji,njk->nik", first, second)
        shift = np.einsum("nji,nj->ni", first, pos[lag:] - pos[:-lag])
        return step, shift

    true_step, true_shift = motion(truth.rotations, truth.positions)
    est_step, est_shift = motion(rotations, positions)
    error_rotation = np.einsum("nji,njk->nik", true_step, est_step)
    error_shift = np.einsum("nji,nj->ni", true_step, est_shift - true_shift)
    return _rms(np.linalg.norm(error_shift, axis=1)), _rms(rotation_angle_deg(error_rotation))


def landmark_truth_views(
    truth: Mapping[str, np.ndarray], targets: Mapping[str, TrackedTarget], frame_index: int
) -> tuple[TruthView, ...]:
    """One view per landmark with ground-truth boxes, scoring the target tied to it (if any)."""
    tied = {t.landmark_id: t for t in targets.values() if t.landmark_id is not None}
    return tuple(
        truth_view(boxes, frame_index, tied.get(landmark_id), label=f"GT {landmark_id}")
        for landmark_id, boxes in truth.items()
    )


def charted_view(views: tuple[TruthView, ...], preferred: tuple[str | None, ...]) -> TruthView:
    """The view the Ground truth tab's charts show: the first target of `preferred` (the one
    chosen in Drag draws, the one started from the ground truth) scored in `views`, else the
    first scored one, else the first."""
    scored = {view.target_id: view for view in views if view.target_id is not None}
    for target_id in preferred:
        if target_id in scored:
            return scored[target_id]
    return next(iter(scored.values()), views[0])
