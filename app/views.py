"""What the worker thread hands the display thread: an immutable snapshot of one frame.

No viser here: `frame_view` builds it from the pipeline on the worker thread, and tests read it
without a browser.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from app.canvas import TargetDrawing, target_colour
from autotrack.pipeline import Pipeline
from autotrack.result import PoseEstimate


@dataclass(frozen=True)
class PoseView:
    """What the 3-D view shows for one frame."""

    frame_index: int
    pose: PoseEstimate | None
    last_valid: PoseEstimate | None
    trajectory_frames: tuple[int, ...]
    trajectory_positions: np.ndarray
    """(n, 3) positions of the valid poses, in frame order."""


@dataclass(frozen=True)
class SignalHistory:
    """Copies of the per-frame signals, taken by the tracking thread for the display thread."""

    target_ids: tuple[str, ...]
    colours: tuple[tuple[int, int, int], ...]
    signals: Mapping[str, Mapping[str, np.ndarray]]
    """Target id -> signal name (see autotrack.pipeline.SIGNAL_NAMES) -> values over all frames."""
    frame_seconds: np.ndarray
    """Tracking time per frame (s), NaN where nothing was tracked."""
    phi: float
    """Aberrance threshold on the global variation."""
    last_frame: int
    """Last frame with any value (-1: nothing yet)."""
    frame_count: int
    """Frames in the sequence (the x axis spans them all)."""


@dataclass(frozen=True)
class FrameView:
    """Everything the display needs for one frame."""

    frame_index: int
    frame_count: int
    frame: np.ndarray
    drawings: Mapping[str, TargetDrawing]
    """Target id -> what to draw for it, for targets with a result on this frame, in order."""
    pose_view: PoseView | None
    """None without a scene."""
    history: SignalHistory
    status: str
    """The status line (markdown)."""


def frame_view(run: Pipeline, frame_index: int, selected: str | None, message: str) -> FrameView:
    """The snapshot of `run` at `frame_index` (`selected`: the target drawn thicker;
    `message`: the tab's last message, under the status line)."""
    drawings: dict[str, TargetDrawing] = {}
    signals: dict[str, dict[str, np.ndarray]] = {}
    colours: list[tuple[int, int, int]] = []
    for target in run.targets.values():
        colour = target_colour(target.number - 1)
        colours.append(colour)
        signals[target.id] = {name: values.copy() for name, values in target.signals.items()}
        result = target.results.get(frame_index)
        if result is None:
            continue
        label = target.id if target.landmark_id is None else f"{target.id}:{target.landmark_id}"
        drawings[target.id] = TargetDrawing(
            label=label,
            colour=colour,
            box=result.box,
            result=result,
            selected=target.id == selected,
        )
    history = SignalHistory(
        target_ids=tuple(run.targets),
        colours=tuple(colours),
        signals=signals,
        frame_seconds=run.frame_seconds.copy(),
        phi=run.params.phi,
        last_frame=run.furthest_frame,
        frame_count=run.frame_count,
    )
    pose_view = _pose_view(run, frame_index)
    return FrameView(
        frame_index=frame_index,
        frame_count=run.frame_count,
        frame=run.frame(frame_index),
        drawings=drawings,
        pose_view=pose_view,
        history=history,
        status=status_text(
            run, frame_index, None if pose_view is None else pose_view.pose, message
        ),
    )


def _pose_view(run: Pipeline, frame_index: int) -> PoseView | None:
    if run.scene is None:
        return None
    trajectory = list(run.valid_positions())
    last_valid = next(
        (
            run.poses[index]
            for index in sorted(run.poses, reverse=True)
            if index <= frame_index and run.poses[index].valid
        ),
        None,
    )
    return PoseView(
        frame_index=frame_index,
        pose=run.poses.get(frame_index),
        last_valid=last_valid,
        trajectory_frames=tuple(index for index, _ in trajectory),
        trajectory_positions=np.array([position for _, position in trajectory]).reshape(-1, 3),
    )


def status_text(run: Pipeline, frame_index: int, pose: PoseEstimate | None, message: str) -> str:
    """The status line: sequence, frame, tracking progress, pose, then the last message."""
    parts = [
        f"**{run.frames.name}** · frame {frame_index + 1} / {run.frame_count}",
        f"tracked to {run.tracked_until + 1}" if run.targets else "no targets",
    ]
    if pose is not None:
        parts.append(pose_text(pose))
    text = " · ".join(parts)
    return f"{text}\n\n{message}" if message else text


def pose_text(pose: PoseEstimate) -> str:
    """One line about a pose for the status bar."""
    if not pose.valid:
        return f"pose invalid: {pose.reason}"
    x, y, z = (float(v) for v in pose.position)
    return f"camera at ({x:.2f}, {y:.2f}, {z:.2f}) m, {pose.rms_error_px:.2f} px RMS"
