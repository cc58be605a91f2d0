"""Resuming a recorded session: its history into a new pipeline, live targets restarted."""

from __future__ import annotations

from typing import TYPE_CHECKING

from autotrack.pipeline.targets import TrackedTarget, number_of
from autotrack.result import PoseEstimate
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
    recorded_poses = session.pose_estimates()
    for frame_index, pose in sorted(recorded_poses.items()):
        if frame_index < resume_frame:
            _keep_pose(pipeline, pose)
    for frame_index, boxes in sorted(restarts.items()):
        started = pipeline._timed_start(frame_index, boxes)
        for target_id, result in started.items():
            target = pipeline.targets[target_id]
            pipeline._restart(target, target.results.get(frame_index, result))
    # The restarts solved the resume frame again from its recorded boxes, with a localiser
    # that has no history (no continuity prior, no peak scores): the recorded pose is the one
    # the session showed there, so it stays.
    if resume_frame in recorded_poses and resume_frame in pipeline.poses:
        _keep_pose(pipeline, recorded_poses[resume_frame])
    pipeline.resume_frame = resume_frame
    pipeline._log_event("session_resumed", resume_frame, None, source=str(session.path))


def _keep_pose(pipeline: Pipeline, pose: PoseEstimate) -> None:
    """A recorded pose becomes the pipeline's (and the new recording's) pose of its frame."""
    pipeline.poses[pose.frame_index] = pose
    recorder = pipeline._recorder_or_none()
    if recorder is not None:
        recorder.log_pose(pose)
