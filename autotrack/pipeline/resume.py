"""Resuming a recorded session: its history into a new pipeline, live targets restarted."""

from __future__ import annotations

from typing import TYPE_CHECKING

from autotrack.pipeline.targets import TrackedTarget, number_of
from autotrack.sessions import Session

if TYPE_CHECKING:
    from autotrack.pipeline.pipeline import Pipeline

Box = tuple[float, float, float, float]


def restore(pipeline: Pipeline, session: Session) -> None:
    """Make `session`'s results and poses the pipeline's history and restart every live
    target from its last recorded box (`Pipeline.resume`)."""
    live = {
        target_id: target
        for target_id, target in session.recorded_targets().items()
        if target.last_box is not None and 0 <= target.last_box[0] < pipeline.frame_count
    }
    restarts: dict[int, dict[str, Box]] = {}
    for target_id, recorded in live.items():
        frame_index, box = recorded.last_box
        restarts.setdefault(frame_index, {})[target_id] = box
    resume_frame = min(restarts, default=0)
    for position, (target_id, recorded) in enumerate(live.items()):
        landmark = recorded.landmark_id
        if pipeline.scene is None or landmark not in pipeline.scene.landmark_ids:
            landmark = None
        number = number_of(target_id, position + 1)
        target = TrackedTarget.new(target_id, number, landmark, pipeline.frame_count)
        pipeline.targets[target_id] = target
        for frame_index, result in sorted(recorded.results.items()):
            if frame_index <= recorded.last_box[0]:
                pipeline._store(target, result)
    for frame_index, pose in sorted(session.pose_estimates().items()):
        if frame_index < resume_frame:
            pipeline.poses[frame_index] = pose
            recorder = pipeline._recorder_or_none()
            if recorder is not None:
                recorder.log_pose(pose)
    for frame_index, boxes in sorted(restarts.items()):
        started = pipeline._timed_start(frame_index, boxes)
        for target_id, result in started.items():
            target = pipeline.targets[target_id]
            pipeline._restart(target, target.results.get(frame_index, result))
    pipeline.resume_frame = resume_frame
    pipeline._log_event("session_resumed", resume_frame, None, source=str(session.path))
