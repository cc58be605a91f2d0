"""What the worker thread hands the display thread: an immutable snapshot of one frame.

No viser here: `frame_view` builds it from the pipeline on the worker thread, and tests read it
without a browser.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace

import numpy as np

from autotrack.errors import SessionError
from autotrack.localization.smoothing import SmootherParams, smoothed_positions
from autotrack.pipeline import Pipeline, TrackedTarget
from autotrack.result import PoseEstimate, TrackResult
from autotrack.sessions.maps import FrameMaps
from autotrack_studio.browser_text import markdown_literal
from autotrack_studio.canvas import TargetDrawing, target_colour
from autotrack_studio.groundtruth import TruthPoses, TruthView

RecordedMaps = Callable[[str, int], FrameMaps | None]
"""(target id, frame) -> that target's maps on the frame as recorded (None: not at hand): where
the maps of a frame outside the run's map window come from."""

DEFAULT_FPS = 10.0
"""Frame rate the smoother assumes when the sequence has none."""


@dataclass(frozen=True)
class PoseView:
    """What the 3-D view shows for one frame."""

    frame_index: int
    pose: PoseEstimate | None
    last_valid: PoseEstimate | None
    trajectory_frames: tuple[int, ...]
    trajectory_positions: np.ndarray
    """(n, 3) positions of the valid poses, in frame order."""
    poses: Mapping[int, PoseEstimate]
    """Every pose so far by frame (for the smoothed trajectory)."""
    fps: float
    """The sequence's frame rate (the smoother's time step)."""


def smoothed_view(view: PoseView) -> PoseView:
    """`view` with the smoothed trajectory (constant-velocity Kalman with a 3-frame fixed-lag
    smoother) in place of the raw one; gaps stay gaps."""
    smoothed = smoothed_positions(view.poses, SmootherParams(fps=view.fps))
    return replace(
        view,
        trajectory_frames=tuple(index for index, _ in smoothed),
        trajectory_positions=np.array([position for _, position in smoothed]).reshape(-1, 3),
    )


@dataclass(frozen=True)
class SignalHistory:
    """Copies of the per-frame signals, taken by the tracking thread for the display thread."""

    target_ids: tuple[str, ...]
    colours: tuple[tuple[int, int, int], ...]
    signals: Mapping[str, Mapping[str, np.ndarray]]
    """Target id -> signal name (see autotrack.pipeline.SIGNAL_NAMES) -> values over all frames."""
    frame_seconds: np.ndarray
    """Tracking time per frame (s), NaN where nothing was tracked."""
    play_seconds: np.ndarray
    """Time from the previous frame to this one while playing in the app (s), else NaN."""
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
    truth: TruthView | None = None
    """The ground truth the Ground truth tab charts (None: the sequence has none)."""
    truths: tuple[TruthView, ...] = ()
    """Every target's ground truth on this frame and its live scores (one per landmark with
    ground truth, or the one target of a benchmark sequence)."""
    truth_poses: TruthPoses | None = None
    """The ground-truth camera poses (the display computes the pose error from them)."""
    playing: bool = False
    """Whether playback (or a live run) goes on past this frame (the display then sends less
    often what the browser spends the most drawing)."""


def frame_view(
    run: Pipeline,
    frame_index: int,
    selected: str | None,
    message: str,
    play_seconds: np.ndarray | None = None,
    truth: TruthView | None = None,
    *,
    truths: tuple[TruthView, ...] = (),
    truth_poses: TruthPoses | None = None,
    playing: bool = False,
) -> FrameView:
    """The snapshot of `run` at `frame_index` (`selected`: the target drawn thicker;
    `message`: the tab's last message, under the status line; `play_seconds`: the in-app time
    per played frame). The maps of frames outside the run's map window are read back from its
    recording."""
    recorded = run.recorded_maps
    if play_seconds is None:
        play_seconds = np.full(run.frame_count, np.nan)
    drawings: dict[str, TargetDrawing] = {}
    signals: dict[str, dict[str, np.ndarray]] = {}
    colours: list[tuple[int, int, int]] = []
    for target in run.targets.values():
        colour = target_colour(target.number - 1)
        colours.append(colour)
        signals[target.id] = target.signals  # new arrays
        result = with_maps(target, frame_index, recorded)
        if result is None:
            continue
        label = target.id if target.landmark_id is None else f"{target.id}:{target.landmark_id}"
        previous = with_maps(target, frame_index - 1, recorded)
        weights_frame = trained_frame(target, frame_index)
        weights = None if weights_frame is None else with_maps(target, weights_frame, recorded)
        drawings[target.id] = TargetDrawing(
            label=label,
            colour=colour,
            box=result.box,
            result=result,
            selected=target.id == selected,
            previous_response=None if previous is None else previous.response_map,
            weights=None if weights is None else weights.spatial_window,
            weights_frame=weights_frame,
        )
    history = SignalHistory(
        target_ids=tuple(run.targets),
        colours=tuple(colours),
        signals=signals,
        frame_seconds=run.frame_seconds.copy(),
        play_seconds=play_seconds.copy(),
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
            run,
            frame_index,
            None if pose_view is None else pose_view.pose,
            message,
            rates_text(run.frame_seconds, play_seconds, frame_index),
        ),
        truth=truth,
        truths=truths or (() if truth is None else (truth,)),
        truth_poses=truth_poses,
        playing=playing,
    )


WEIGHTS_LOOKBACK = 100
"""Frames `trained_frame` looks back for the last training (aberrant frames do not train)."""


def trained_frame(target: TrackedTarget, frame_index: int) -> int | None:
    """The last frame at or before `frame_index` whose result carries the spatial weights the
    filter was trained with (an aberrant frame keeps the filter, and its weights, of the last
    training), within WEIGHTS_LOOKBACK frames. Outside the map window, where results keep no
    maps, the frames that trained are those not aberrant."""
    for index in range(frame_index, max(-1, frame_index - WEIGHTS_LOOKBACK), -1):
        result = target.results.get(index)
        if result is None:
            continue
        if result.spatial_window is not None if index >= target.maps_from else not result.aberrant:
            return index
    return None


def with_maps(
    target: TrackedTarget, frame_index: int, recorded: RecordedMaps | None
) -> TrackResult | None:
    """The target's result on `frame_index` with its maps: kept in memory inside the run's map
    window, else read back through `recorded` (none when it has none)."""
    result = target.results.get(frame_index)
    if result is None or frame_index >= target.maps_from or recorded is None:
        return result
    try:
        maps = recorded(target.id, frame_index)
    except SessionError:  # the file went away or is damaged: the frame shows without maps
        return result
    if maps is None:
        return result
    return replace(
        result,
        response_map=maps.response,
        local_variation=maps.local_variation,
        spatial_window=maps.spatial_window,
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
        poses=dict(run.poses),
        fps=run.fps or DEFAULT_FPS,
    )


RATE_WINDOW = 10
"""Frames the status line's rates average over."""


def rates_text(frame_seconds: np.ndarray, play_seconds: np.ndarray, frame_index: int) -> str:
    """'played at N frames/s in the app · trackers alone M frames/s' over the RATE_WINDOW frames
    up to `frame_index` ('' when nothing was played there)."""
    start = max(0, frame_index - RATE_WINDOW + 1)
    played = play_seconds[start : frame_index + 1]
    played = played[np.isfinite(played)]
    if played.size == 0:
        return ""
    tracked = frame_seconds[start : frame_index + 1]
    tracked = tracked[np.isfinite(tracked)]
    alone = f" · trackers alone {1.0 / tracked.mean():.1f} frames/s" if tracked.size else ""
    return f"played at {1.0 / played.mean():.1f} frames/s in the app{alone}"


def status_text(
    run: Pipeline, frame_index: int, pose: PoseEstimate | None, message: str, rates: str = ""
) -> str:
    """The status line: sequence, frame, tracking progress, rates, pose, then the message."""
    parts = [
        f"**{markdown_literal(run.frames.name)}** · frame {frame_index + 1} / {run.frame_count}",
        f"tracked to {run.tracked_until + 1}" if run.targets else "no targets",
    ]
    if rates:
        parts.append(rates)
    if pose is not None:
        parts.append(pose_text(pose))
    text = " · ".join(parts)
    return f"{text}\n\n{markdown_literal(message)}" if message else text


def pose_text(pose: PoseEstimate) -> str:
    """One line about a pose for the status bar."""
    if not pose.valid:
        return f"pose invalid: {pose.reason}"
    x, y, z = (float(v) for v in pose.position)
    return f"camera at ({x:.2f}, {y:.2f}, {z:.2f}) m, {pose.rms_error_px:.2f} px RMS"
