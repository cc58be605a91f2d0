"""The pipeline: frames -> targets -> camera pose -> session recording, one frame at a time.

It owns frame indexing and timing (as pytracking's runner does): trackers only answer for the
frame they are given, the localiser only for the points it is given, and the recorder writes
what the pipeline hands it. The command line (`track`, `localize`), `localize_sequence`, the
benchmark scripts and the app all drive this one class.

Targets are named "T1", "T2", ... in the order they are added, whatever the caller (a deleted
target's number is given to the next new one, so ids stay T1..Tn); a target that localises a
scene landmark carries its id (`landmark_id`). Editing a box at an earlier frame re-tracks
only that target from there; the other targets keep their results and filters.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from types import EllipsisType
from typing import Any

import numpy as np

from autotrack.errors import InputError
from autotrack.hybrid.factory import tracker_name
from autotrack.io.frames import FrameCache, FrameSource
from autotrack.localization.localizer import LocalizerParams
from autotrack.localization.reacquire import ReacquireParams
from autotrack.localization.refine import RefineParams
from autotrack.localization.scene import Scene
from autotrack.params import TrackerParams
from autotrack.pipeline.groups import TrackerGroups
from autotrack.pipeline.posing import LandmarkEntry, PoseStage
from autotrack.pipeline.recording import Recording, open_recorder
from autotrack.pipeline.targets import (
    FrameOutcome,
    TrackedTarget,
    check_landmark,
    checked_box,
    free_numbers,
    grown,
    number_of,
)
from autotrack.result import PoseEstimate, TrackResult
from autotrack.sessions import Session, SessionRecorder
from autotrack.sessions.maps import FrameMaps, SessionMaps
from autotrack.sessions.messages import landmark_positions
from autotrack.tracker.parallel.target_process import WorkerPool

Box = tuple[float, float, float, float]

FRAME_CACHE = 8
"""Decoded frames kept for stepping back and forth without decoding again."""
MAP_WINDOW = 300
"""Frames (per target, back from its newest) whose results keep their maps by default."""


class Pipeline:
    """Targets, trackers, results and poses of one sequence, recorded as it goes.

    Args:
        frames: The sequence.
        params: Tracker parameters for every target (for the hybrid: its correlation
            filter's; `autotrack.hybrid.factory.tracker_params` gives a tracker's own).
        tracker: `nanotrack` or `hybrid` to track every target with them
            (`autotrack.hybrid.factory`; in threads, never child processes); None or a preset
            name: AutoTrack with `params`. `tracker_name` says which one runs.
        scene: Localisation scene (None: no poses).
        localizer_params: Localiser settings (None: the library defaults).
        recording: Where to record the session (None: not recorded).
        fps: Frame rate of the log times (None: the frames' own, else the recorder's default).
        tracker_threads: Threads each MultiTracker may use for its targets.
        tracker_processes, worker_pool: Processes each MultiTracker spreads its targets over,
            and the pool lending it the child processes (`MultiTracker`; None: its own).
        refine_params: Sub-pixel landmark points (`localization.refine`; None: box centres).
        reacquire_params: Out-of-view gate and re-acquisition of lost landmarks
            (`localization.reacquire`; None: off). Both need a scene.
        map_window: Frames whose results keep their response, local-variation and spatial
            maps, back from each target's newest (older results keep boxes and signals only;
            the recording has every map). 1: the newest only; 0: none.
    """

    def __init__(
        self,
        frames: FrameSource,
        params: TrackerParams,
        *,
        tracker: str | None = None,
        scene: Scene | None = None,
        localizer_params: LocalizerParams | None = None,
        recording: Recording | None = None,
        fps: float | None = None,
        tracker_threads: int = 1,
        tracker_processes: int = 1,
        worker_pool: WorkerPool | None = None,
        refine_params: RefineParams | None = None,
        reacquire_params: ReacquireParams | None = None,
        map_window: int = MAP_WINDOW,
    ) -> None:
        if tracker_threads < 1:
            raise InputError(f"tracker threads must be at least 1, got {tracker_threads}")
        if map_window < 0:
            raise InputError(f"the map window must be 0 frames or more, got {map_window}")
        if scene is not None:
            scene.camera.check_image_size(*frames.frame_size)
        self.frames = frames
        self.params = params
        self.tracker_name = tracker_name(tracker, params)
        """The tracker every target runs: `nanotrack`, `hybrid` or the AutoTrack preset name
        of `params` (recorded in the session)."""
        self.scene = scene
        self.recording = recording
        self.fps = fps if fps is not None else frames.fps
        self.frame_count = len(frames)
        self.map_window = map_window
        self.targets: dict[str, TrackedTarget] = {}
        self.poses: dict[int, PoseEstimate] = {}
        self.frame_seconds = np.full(self.frame_count, np.nan)
        """Tracking time of each frame (every tracker that ran on it), seconds."""
        self.resumed_from: Path | None = None
        self.resume_frame = 0
        """After `resume`: the frame tracking continues from."""
        self._groups = TrackerGroups(
            params, tracker_threads, tracker_processes, worker_pool, self.tracker_name
        )
        self._posing = (
            None
            if scene is None
            else PoseStage(scene, localizer_params, refine_params, reacquire_params)
        )
        self._last_pose_frame = -1
        self._frame_cache = FrameCache(frames, FRAME_CACHE)
        self._recorder: SessionRecorder | None = None
        self._recorded_maps: SessionMaps | None = None
        self._embedded: set[int] = set()

    @classmethod
    def resume(
        cls,
        session: Session,
        frames: FrameSource,
        *,
        scene: Scene | None = None,
        localizer_params: LocalizerParams | None = None,
        recording: Recording | None = None,
        fps: float | None = None,
        tracker_threads: int = 1,
        **pose_options: Any,
    ) -> Pipeline:
        """Continue a recorded session on `frames` with its recorded tracker and parameters.

        Its results and poses become this pipeline's history (copied into the new recording,
        which names the session as `resumed_from`), and each live target restarts from its
        last recorded box; `resume_frame` is the earliest restart. Filters are not stored in a
        session, so a restarted target learns afresh from its last box (and, with
        `pose_options` refine_params, its template from that box).
        """
        pipeline = cls(
            frames,
            session.tracker_params(),
            tracker=session.tracker_name,
            scene=scene,
            localizer_params=localizer_params,
            recording=recording,
            fps=fps,
            tracker_threads=tracker_threads,
            **pose_options,
        )
        pipeline.resumed_from = session.path
        pipeline._restore(session)
        return pipeline

    def _restore(self, session: Session) -> None:
        """Make `session`'s results and poses this pipeline's history and restart every live
        target from its last recorded box."""
        live = {
            target_id: target
            for target_id, target in session.recorded_targets().items()
            if target.last_box is not None and 0 <= target.last_box[0] < self.frame_count
        }
        restarts: dict[int, dict[str, Box]] = {}
        for target_id, recorded in live.items():
            frame_index, box = recorded.last_box
            restarts.setdefault(frame_index, {})[target_id] = box
        resume_frame = min(restarts, default=0)
        for position, (target_id, recorded) in enumerate(live.items()):
            landmark = recorded.landmark_id
            if self.scene is None or landmark not in self.scene.landmark_ids:
                landmark = None
            number = number_of(target_id, position + 1)
            target = TrackedTarget.new(target_id, number, landmark, self.frame_count)
            self.targets[target_id] = target
            for frame_index, result in sorted(recorded.results.items()):
                if frame_index <= recorded.last_box[0]:
                    self._store(target, result)
        recorded_poses = session.pose_estimates()
        for frame_index, pose in sorted(recorded_poses.items()):
            if frame_index < resume_frame:
                self._keep_pose(pose)
        for frame_index, boxes in sorted(restarts.items()):
            started = self._timed_start(frame_index, boxes)
            for target_id, result in started.items():
                target = self.targets[target_id]
                self._restart(target, target.results.get(frame_index, result))
        # The restarts solved the resume frame again from its recorded boxes, with a localiser
        # that has no history (no continuity prior, no peak scores): the recorded pose is the
        # one the session showed there, so it stays.
        if resume_frame in recorded_poses and resume_frame in self.poses:
            self._keep_pose(recorded_poses[resume_frame])
        self.resume_frame = resume_frame
        self._log_event("session_resumed", resume_frame, None, source=str(session.path))

    def _keep_pose(self, pose: PoseEstimate) -> None:
        """A recorded pose becomes this pipeline's (and the new recording's) pose of its frame."""
        self.poses[pose.frame_index] = pose
        recorder = self._recorder_or_none()
        if recorder is not None:
            recorder.log_pose(pose)

    # -- frames -------------------------------------------------------------------------------

    def frame(self, index: int) -> np.ndarray:
        """Frame `index` (RGB uint8), from a small cache."""
        return self._frame_cache.read(index)

    # -- recording ----------------------------------------------------------------------------

    @property
    def session_path(self) -> Path | None:
        """The recording's file (None until the first edit, or when not recording)."""
        return None if self._recorder is None else self._recorder.path

    @property
    def recording_error(self) -> OSError | None:
        """The write that stopped the recording (a full disk, ...; `SessionRecorder.write_error`):
        the file keeps what was recorded before it; None while recording works."""
        return None if self._recorder is None else self._recorder.write_error

    def flush(self) -> None:
        """Hand everything recorded so far to the OS (e.g. before exporting the session)."""
        if self._recorder is not None:
            self._recorder.flush()

    def recorded_maps(self, target_id: str, frame_index: int) -> FrameMaps | None:
        """A target's maps on a frame as recorded (the results outside `map_window` keep none),
        read by frame from the session file; None when nothing is recorded."""
        if self._recorder is None:
            return None
        self._recorder.flush()
        if self._recorded_maps is None or self._recorded_maps.path != self._recorder.path:
            self._recorded_maps = SessionMaps(self._recorder.path)
        return self._recorded_maps.frame_maps(target_id, frame_index)

    def _recorder_or_none(self) -> SessionRecorder | None:
        if self._recorder is None and self.recording is not None:
            if self.scene is not None:
                landmark_positions(self.scene)  # its ids are refused before the file exists
            self._recorder = open_recorder(
                self.recording,
                self.params,
                self.tracker_name,
                self.fps,
                self.resumed_from,
                self.frames,
            )
            if self.scene is not None:
                self._recorder.log_landmarks(self.scene)
        return self._recorder

    def _embed_frame(self, frame_index: int) -> None:
        """The frame itself into the recording, once, when the recording embeds frames: a JPEG
        or PNG file's bytes as they are, any other frame encoded once as JPEG."""
        recorder = self._recorder_or_none()
        if recorder is None or not recorder.embed_frames or frame_index in self._embedded:
            return
        encoded = self.frames.encoded(frame_index)
        if encoded is not None:
            recorder.log_encoded_frame(frame_index, encoded.data, encoded.format)
        else:
            recorder.log_frame(frame_index, self.frame(frame_index))
        self._embedded.add(frame_index)

    def _log_event(self, kind: str, frame_index: int, target_id: str | None, **extra: Any) -> None:
        recorder = self._recorder_or_none()
        if recorder is not None:
            recorder.log_event(kind, frame_index, target_id, **extra)

    def close(self) -> None:
        """Stop the trackers, their processes and the read-ahead; finish the recording."""
        self._groups.close()
        self._frame_cache.close()
        if self._recorder is not None:
            self._recorder.close()
            self._recorder = None

    def __enter__(self) -> Pipeline:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- targets ------------------------------------------------------------------------------

    def free_landmarks(self) -> list[str]:
        """Scene landmarks no target localises yet, in scene order."""
        if self.scene is None:
            return []
        taken = {target.landmark_id for target in self.targets.values()}
        return [landmark for landmark in self.scene.landmark_ids if landmark not in taken]

    def add_target(
        self, frame_index: int, box: Box, landmark_id: str | None | EllipsisType = ...
    ) -> str:
        """A new target with its box on frame `frame_index`; returns its id. `landmark_id=...`
        (the default) assigns the first free scene landmark."""
        if landmark_id is ...:
            free = self.free_landmarks()
            landmark_id = free[0] if free else None
        return self._add(frame_index, [(box, landmark_id)])[0]

    def add_targets(self, frame_index: int, boxes: Mapping[str, Box]) -> list[str]:
        """One target per landmark id -> box, all on frame `frame_index` in one step (one pose
        estimate); returns their ids in the order given."""
        return self._add(frame_index, [(box, landmark) for landmark, box in boxes.items()])

    def _add(self, frame_index: int, entries: list[tuple[Box, str | None]]) -> list[str]:
        if not entries:
            raise InputError("no targets to add: give at least one box")
        self._check_frame(frame_index)
        landmarks = [landmark for _, landmark in entries if landmark is not None]
        if len(set(landmarks)) != len(landmarks):
            raise InputError("each landmark can be tracked by one target only")
        for _, landmark in entries:
            check_landmark(self.scene, self.targets.values(), landmark, None)
        numbers = free_numbers({t.number for t in self.targets.values()}, len(entries))
        frame = self.frame(frame_index)
        boxes = {
            f"T{number}": checked_box(
                frame, box, None if landmark is None else f"landmark {landmark}"
            )
            for number, (box, landmark) in zip(numbers, entries, strict=True)
        }
        results = self._timed_start(frame_index, boxes)
        self._embed_frame(frame_index)
        for number, target_id, (_, landmark) in zip(numbers, boxes, entries, strict=True):
            self.targets[target_id] = TrackedTarget.new(
                target_id, number, landmark, self.frame_count
            )
            self._store(self.targets[target_id], results[target_id])
        self._forget_poses_from(frame_index)
        self._estimate_pose(frame_index)
        for (target_id, box), (_, landmark) in zip(boxes.items(), entries, strict=True):
            self._log_event("box_drawn", frame_index, target_id, box=box, landmark_id=landmark)
        return list(boxes)

    def place_box(self, target_id: str, frame_index: int, box: Box) -> None:
        """Redraw a target's box at `frame_index`: a correction when it was tracked there.

        Results after `frame_index` of this target are dropped; it is re-tracked from here.
        """
        target = self._target(target_id)
        self._check_frame(frame_index)
        box = checked_box(self.frame(frame_index), box, target_id)
        corrected = frame_index in target.results
        result = self._timed_start(frame_index, {target_id: box})[target_id]
        self._restart(target, result)
        kind = "box_corrected" if corrected else "box_drawn"
        self._log_event(kind, frame_index, target_id, box=box)

    def delete_target(self, target_id: str, frame_index: int) -> None:
        """Remove a target, its tracker and its results; poses are re-estimated without it."""
        target = self._target(target_id)
        self._groups.remove(target_id)
        first = min(target.results, default=frame_index)
        recorder = self._recorder_or_none()
        if recorder is not None:
            # "No result" records: a new target given this id later starts clean.
            for index in sorted(target.results):
                recorder.log_no_result(target_id, index, landmark_id=None)
        del self.targets[target_id]
        if self._posing is not None:
            self._posing.remove(target_id, target.landmark_id)
        self._forget_poses_from(first)
        self._log_event("box_deleted", frame_index, target_id)
        self._estimate_pose(frame_index)

    def assign_landmark(self, target_id: str, landmark_id: str | None, frame_index: int) -> None:
        """Make a target localise `landmark_id` (None: none); poses are re-estimated."""
        target = self._target(target_id)
        if target.landmark_id == landmark_id:
            return
        check_landmark(self.scene, self.targets.values(), landmark_id, target_id)
        if self._posing is not None:
            self._posing.landmark_changed(target_id, target.landmark_id, landmark_id)
        target.landmark_id = landmark_id
        self._forget_poses_from(min(target.results, default=0))
        self._log_event("landmark_assigned", frame_index, target_id, landmark_id=landmark_id)
        self._estimate_pose(frame_index)

    def _check_frame(self, frame_index: int) -> None:
        if not 0 <= frame_index < self.frame_count:
            raise InputError(f"frame {frame_index} is outside 0..{self.frame_count - 1}")

    def _target(self, target_id: str) -> TrackedTarget:
        try:
            return self.targets[target_id]
        except KeyError:
            raise InputError(f"no target {target_id!r}") from None

    # -- tracking -----------------------------------------------------------------------------

    @property
    def tracked_until(self) -> int:
        """Last frame every live target has a result for (-1 without targets)."""
        return self._groups.tracked_until

    @property
    def furthest_frame(self) -> int:
        """Last frame any target has a result for (-1 without targets)."""
        return max((target.last_frame for target in self.targets.values()), default=-1)

    def advance(self, frame_index: int, horizon: int | None = None) -> None:
        """Track every target whose tracker is at the previous frame onto `frame_index`, then
        estimate the pose there if it is not known yet. A growing (live) source's new frames
        are taken in first; its previous frame is the last one it did not drop. `horizon`: the
        caller advances frame by frame up to it next (children start the next frame early)."""
        if frame_index >= self.frame_count:
            self._grow()
        if not 0 < frame_index < self.frame_count:
            return
        results, seconds = self._groups.advance(frame_index, self.frames, self.frame, horizon)
        if results:
            self.frame_seconds[frame_index] = seconds
            self._embed_frame(frame_index)
            for target_id, result in results.items():
                self._store(self.targets[target_id], result)
            if self._posing is not None:
                boxes = {k: r.box for k, r in results.items() if self.targets[k].landmark_id}
                self._posing.refine(frame_index, self.frame(frame_index), boxes)
        self._estimate_pose(frame_index)

    def _grow(self) -> None:
        """Take in the frames a growing (live) source delivered since the last call."""
        self.frame_count = len(self.frames)
        self.frame_seconds = grown(self.frame_seconds, self.frame_count)
        for target in self.targets.values():
            target.grow(self.frame_count)

    def track_to(self, frame_index: int, should_stop: Callable[[], bool] | None = None) -> None:
        """Track forward until every target has a result at `frame_index` (or `should_stop`)."""
        frame_index = min(frame_index, self.frame_count - 1)
        while self._groups and self.tracked_until < frame_index:
            if should_stop is not None and should_stop():
                return
            self.advance(self.tracked_until + 1, horizon=frame_index)

    def run(self) -> Iterator[FrameOutcome]:
        """Every frame's outcome from the first frame with a result to the last, tracking the
        frames not tracked yet on the way."""
        first = min(
            (t.results.first_frame for t in self.targets.values() if t.results), default=None
        )
        if first is None:
            raise InputError("no targets to track: add a box first")
        for frame_index in range(first, self.frame_count):
            while self._groups and self.tracked_until < frame_index:
                self.advance(self.tracked_until + 1, horizon=self.frame_count - 1)
            yield self.outcome(frame_index)

    def results_at(self, frame_index: int) -> dict[str, TrackResult]:
        """Target id -> result at `frame_index`, for targets that have one."""
        return {
            target.id: target.results[frame_index]
            for target in self.targets.values()
            if frame_index in target.results
        }

    def outcome(self, frame_index: int) -> FrameOutcome:
        """What is known about frame `frame_index`: results, landmarks, pose."""
        return FrameOutcome(
            frame_index=frame_index,
            tracks=self.results_at(frame_index),
            landmark_ids={t.id: t.landmark_id for t in self.targets.values()},
            pose=self.poses.get(frame_index),
            solver=None if self._posing is None else self._posing.solver_input(frame_index),
        )

    def _timed_start(self, frame_index: int, boxes: Mapping[str, Box]) -> dict[str, TrackResult]:
        frame = self.frame(frame_index)
        started = time.perf_counter()
        results = self._groups.start(frame_index, frame, boxes)
        if self._posing is not None:
            landmarks = {k: t.landmark_id for k, t in self.targets.items()}
            self._posing.start(frame_index, frame, boxes, landmarks)
        elapsed = time.perf_counter() - started
        self.frame_seconds[frame_index] = np.nansum([self.frame_seconds[frame_index], elapsed])
        return results

    def _restart(self, target: TrackedTarget, result: TrackResult) -> None:
        """`result` becomes the target's result on its frame; its later results are dropped."""
        frame_index = result.frame_index
        recorder = self._recorder_or_none()
        for later in target.truncate_after(frame_index):
            if recorder is not None:
                # The recording keeps the latest record per frame: this one says the target has
                # no result there any more (until it is tracked again).
                recorder.log_no_result(target.id, later, landmark_id=target.landmark_id)
        if self._posing is not None:
            self._posing.drop_points(target.id, frame_index + 1)
        self._store(target, result)
        self._forget_poses_from(frame_index)
        self._estimate_pose(frame_index)

    def _store(self, target: TrackedTarget, result: TrackResult, *, record: bool = True) -> None:
        """Keep `result` as the target's result on its frame (and record it, maps included)."""
        target.keep(result, self.map_window)
        recorder = self._recorder_or_none() if record else None
        if recorder is not None:
            recorder.log_target(target.id, result, landmark_id=target.landmark_id)

    # -- localisation -------------------------------------------------------------------------

    def _forget_poses_from(self, first_stale: int) -> None:
        """Drop the poses from `first_stale` on (a box before them changed); the recording
        marks each as superseded, and the localiser starts afresh."""
        recorder = self._recorder_or_none() if self.targets else None
        for index in [index for index in self.poses if index >= first_stale]:
            del self.poses[index]
            if recorder is not None:
                recorder.log_no_pose(index, "discarded: a box was redrawn on an earlier frame")
        if self._posing is not None:
            # The localiser keeps the previous pose as a continuity prior: start it afresh.
            self._posing.forget_from(first_stale)

    def _estimate_pose(self, frame_index: int) -> None:
        if self._posing is None or frame_index in self.poses:
            return
        entries = [
            LandmarkEntry(t.id, t.landmark_id, t.results[frame_index], t.last_frame == frame_index)
            for t in self.targets.values()
            if t.landmark_id is not None and frame_index in t.results
        ]
        if not entries:
            return
        previous = self.frames.previous_index(frame_index)
        pose = self._posing.estimate(frame_index, previous, entries)
        self.poses[frame_index] = pose
        recorder = self._recorder_or_none()
        if recorder is not None:
            recorder.log_pose(pose)
        if not self._posing.reacquiring:
            return
        frame = self.frame(frame_index)
        for restart in self._posing.reacquire(frame_index, frame, pose, entries):
            # The tracker restarts from the found box; this frame keeps its tracked result.
            self._groups.start(frame_index, frame, {restart.target_id: restart.box})
            self._log_event(
                "landmark_reacquired",
                frame_index,
                restart.target_id,
                box=restart.box,
                landmark_id=restart.landmark_id,
            )

    def valid_positions(self) -> Iterator[tuple[int, np.ndarray]]:
        """(frame index, camera position) of the valid poses, in frame order."""
        for index in sorted(self.poses):
            pose = self.poses[index]
            if pose.valid:
                yield index, np.asarray(pose.position, dtype=np.float64)
