"""One tab's tracking run: targets, their trackers, per-frame results, poses and the recording.

No viser here, so the whole flow can be driven and tested without a browser.

Trackers are grouped: a group is one `MultiTracker` whose targets all sit at the same last
tracked frame (its head). Boxes drawn on the same frame join one group, so the usual case (four
boxes on frame 1, then play) is a single `MultiTracker`. A box redrawn at frame k on a target
whose group is at k is a `reset_target`; redrawn at an earlier frame (after stepping back), the
target leaves its group, loses its results after k, and restarts from k in the group at k (or a
new one). Other targets keep their results and filters: the correction re-tracks only the
corrected target, and playing forward re-tracks it through frames the others already have.
"""

from __future__ import annotations

import re
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import EllipsisType
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from autotrack.errors import InputError
from autotrack.frames import FrameSource
from autotrack.localize import Localizer, LocalizerParams, PoseEstimate
from autotrack.multi import MultiTracker
from autotrack.params import TrackerParams
from autotrack.result import TrackResult
from autotrack.scene import Scene
from autotrack.sessions import Session, SessionRecorder

Box = tuple[float, float, float, float]

FRAME_CACHE = 8
"""Decoded frames kept for stepping back and forth without decoding again."""

SIGNAL_NAMES = ("peak_score", "global_variation", "theta_ref", "theta", "aberrant")
"""Per-target, per-frame numbers the plots show."""


@dataclass
class Target:
    """One tracked object as the user defined it."""

    id: str
    """'T1', 'T2', ... in the order the boxes were drawn; never reused within a run."""
    number: int
    """1, 2, ...: the number in the id (also picks the drawing colour)."""
    landmark_id: str | None
    """Scene landmark this target localises (None: tracked only)."""
    results: dict[int, TrackResult] = field(default_factory=dict)
    """Results by 0-based frame index (the drawn box's frame holds the init result)."""
    signals: dict[str, np.ndarray] = field(default_factory=dict)
    """Name in SIGNAL_NAMES -> float64 array over all frames, NaN where nothing is known."""

    @property
    def last_frame(self) -> int:
        """Last frame with a result (-1 before the box is drawn)."""
        return max(self.results, default=-1)


@dataclass
class _Group:
    """Targets tracked together by one MultiTracker, all at frame `head`."""

    tracker: MultiTracker
    head: int
    target_ids: list[str]


class TrackingRun:
    """Targets, trackers, results and poses of one sequence in one tab, recorded as it goes.

    Args:
        frames: The sequence.
        source: What the recording names as the source (the sequence path).
        params: Tracker parameters for every target.
        scene: Localisation scene (None: no poses).
        scene_path: The scene file (recorded in the session metadata).
        sessions_dir: Folder for the session recording (None: not recorded).
        localizer_params: Localiser settings (None: the library defaults).
        tracker_threads: Threads each MultiTracker may use for its targets.
        session_name: Name part of the recording's file name.
    """

    def __init__(
        self,
        frames: FrameSource,
        *,
        source: str,
        params: TrackerParams,
        scene: Scene | None = None,
        scene_path: Path | None = None,
        sessions_dir: Path | None = None,
        localizer_params: LocalizerParams | None = None,
        tracker_threads: int = 1,
        session_name: str | None = None,
    ) -> None:
        self.frames = frames
        self.source = source
        self.params = params
        self.scene = scene
        self.scene_path = scene_path
        self.sessions_dir = sessions_dir
        self.localizer_params = localizer_params or LocalizerParams()
        self.tracker_threads = tracker_threads
        self.session_name = session_name or frames.name
        self.frame_count = len(frames)
        self.targets: dict[str, Target] = {}
        self.poses: dict[int, PoseEstimate] = {}
        self.frame_seconds = np.full(self.frame_count, np.nan)
        """Tracking time of each frame (all groups that advanced on it), seconds."""
        self._groups: list[_Group] = []
        self._localizer = None if scene is None else Localizer(scene, self.localizer_params)
        self._last_pose_frame = -1
        self._next_number = 1
        self._frame_cache: OrderedDict[int, np.ndarray] = OrderedDict()
        self.recorder: SessionRecorder | None = None
        self.resumed_from: Path | None = None

    # -- frames -------------------------------------------------------------------------------

    def frame(self, index: int) -> np.ndarray:
        """Frame `index` (RGB uint8), from a small cache."""
        if not 0 <= index < self.frame_count:
            raise InputError(f"frame {index} is outside 0..{self.frame_count - 1}")
        cached = self._frame_cache.get(index)
        if cached is not None:
            self._frame_cache.move_to_end(index)
            return cached
        image = self.frames.read(index)
        self._frame_cache[index] = image
        if len(self._frame_cache) > FRAME_CACHE:
            self._frame_cache.popitem(last=False)
        return image

    # -- recording ----------------------------------------------------------------------------

    @property
    def session_path(self) -> Path | None:
        """The recording's file (None until the first box is drawn, or when not recording)."""
        return None if self.recorder is None else Path(self.recorder.path)

    def _recording(self) -> SessionRecorder | None:
        if self.recorder is None and self.sessions_dir is not None:
            self.recorder = SessionRecorder.create(
                self.sessions_dir,
                source=self.source,
                tracker_params=self.params,
                scene_path=self.scene_path,
                fps=self.frames.fps,
                name=self.session_name,
                resumed_from=self.resumed_from,
            )
            if self.scene is not None:
                self.recorder.log_landmarks(self.scene)
        return self.recorder

    def _log_event(self, kind: str, frame_index: int, target_id: str | None, **extra: Any) -> None:
        recorder = self._recording()
        if recorder is not None:
            recorder.log_event(kind, frame_index, target_id, **extra)

    def _log_result(self, target: Target, result: TrackResult) -> None:
        recorder = self._recording()
        if recorder is not None:
            recorder.log_target(target.id, result, landmark_id=target.landmark_id)

    def close(self) -> None:
        """Stop the trackers' threads and finish the recording (the file is readable without
        this, up to its last flush)."""
        for group in self._groups:
            group.tracker.close()
        self._groups.clear()
        if self.recorder is not None:
            self.recorder.close()
            self.recorder = None

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
        """A new target with its box on frame `frame_index`; returns its id.

        `landmark_id=...` (the default) assigns the first free scene landmark.
        """
        if landmark_id is ...:
            free = self.free_landmarks()
            landmark_id = free[0] if free else None
        self._check_landmark(landmark_id, None)
        target_id = f"T{self._next_number}"
        target = Target(
            id=target_id,
            number=self._next_number,
            landmark_id=landmark_id,
            signals={name: np.full(self.frame_count, np.nan) for name in SIGNAL_NAMES},
        )
        self.targets[target_id] = target
        try:
            self._start_tracking(target, frame_index, box)
        except Exception:
            del self.targets[target_id]
            raise
        self._next_number += 1
        self._log_event("box_drawn", frame_index, target_id, box=box, landmark_id=landmark_id)
        return target_id

    def place_box(self, target_id: str, frame_index: int, box: Box) -> None:
        """Redraw a target's box at `frame_index`: a correction when it was tracked there.

        Results after `frame_index` of this target are dropped; it is re-tracked from here.
        """
        target = self._target(target_id)
        corrected = frame_index in target.results
        self._start_tracking(target, frame_index, box)
        kind = "box_corrected" if corrected else "box_drawn"
        self._log_event(kind, frame_index, target_id, box=box)

    def delete_target(self, target_id: str, frame_index: int) -> None:
        """Remove a target, its tracker and its results; poses are re-estimated without it."""
        target = self._target(target_id)
        self._leave_group(target_id)
        first = min(target.results, default=frame_index)
        del self.targets[target_id]
        self._drop_poses_from(first)
        self._log_event("box_deleted", frame_index, target_id)
        self._estimate_pose(frame_index)

    def assign_landmark(self, target_id: str, landmark_id: str | None, frame_index: int) -> None:
        """Make a target localise `landmark_id` (None: none); poses are re-estimated."""
        target = self._target(target_id)
        if target.landmark_id == landmark_id:
            return
        self._check_landmark(landmark_id, target_id)
        target.landmark_id = landmark_id
        self._drop_poses_from(min(target.results, default=0))
        self._log_event("landmark_assigned", frame_index, target_id, landmark_id=landmark_id)
        self._estimate_pose(frame_index)

    def _check_landmark(self, landmark_id: str | None, target_id: str | None) -> None:
        if landmark_id is None:
            return
        if self.scene is None:
            raise InputError("no scene is loaded, so boxes cannot be tied to landmarks")
        if landmark_id not in self.scene.landmark_ids:
            known = ", ".join(self.scene.landmark_ids)
            raise InputError(f"unknown landmark {landmark_id!r}; the scene has {known}")
        for other in self.targets.values():
            if other.id != target_id and other.landmark_id == landmark_id:
                raise InputError(f"landmark {landmark_id} is already tracked by {other.id}")

    def _target(self, target_id: str) -> Target:
        try:
            return self.targets[target_id]
        except KeyError:
            raise InputError(f"no target {target_id!r}") from None

    # -- tracker groups -----------------------------------------------------------------------

    def _group_of(self, target_id: str) -> _Group | None:
        return next((group for group in self._groups if target_id in group.target_ids), None)

    def _leave_group(self, target_id: str, group: _Group | None = None) -> None:
        group = group or self._group_of(target_id)
        if group is None:
            return
        group.target_ids.remove(target_id)
        if group.target_ids:
            group.tracker.remove_target(target_id)
        else:
            group.tracker.close()
            self._groups.remove(group)

    def _start_tracking(
        self, target: Target, frame_index: int, box: Box, kept: TrackResult | None = None
    ) -> None:
        """(Re)initialise `target` on `frame_index` with `box` and drop its later results.

        The init result becomes the target's result there, unless `kept` (a recorded result
        to keep as history) is given. If the tracker refuses the box, nothing changes.
        """
        frame = self.frame(frame_index)
        current = self._group_of(target.id)
        if current is not None and current.head == frame_index:
            result = current.tracker.reset_target(target.id, frame, box)
        else:
            joined = next((g for g in self._groups if g.head == frame_index), None)
            if joined is not None:
                result = joined.tracker.add_target(target.id, frame, box)
                joined.target_ids.append(target.id)
            else:
                tracker = MultiTracker(self.params, [target.id], threads=self.tracker_threads)
                try:
                    result = tracker.init(frame, {target.id: box})[target.id]
                except Exception:
                    tracker.close()
                    raise
                self._groups.append(_Group(tracker, frame_index, [target.id]))
            if current is not None:
                self._leave_group(target.id, current)
        for later in [index for index in target.results if index > frame_index]:
            del target.results[later]
            # The recording keeps the latest record per frame: a record without a box says
            # this target has no result there any more (until it is tracked again).
            self._log_result(target, discarded_result(later))
        for values in target.signals.values():
            values[frame_index:] = np.nan
        self._store(target, kept if kept is not None else result, frame_index)
        self._drop_poses_from(frame_index)
        self._estimate_pose(frame_index)

    def _store(self, target: Target, result: TrackResult, frame_index: int) -> None:
        """Keep `result` as the target's result on sequence frame `frame_index` (a group
        numbers its results from the frame it started on, so they are renumbered here)."""
        result = replace(result, frame_index=frame_index)
        target.results[frame_index] = result
        values = {
            "peak_score": result.peak_score,
            "global_variation": result.global_variation,
            "theta_ref": result.theta_ref,
            "theta": result.theta,
            "aberrant": 1.0 if result.aberrant else 0.0,
        }
        for name, value in values.items():
            target.signals[name][frame_index] = value
        self._log_result(target, result)

    # -- tracking -----------------------------------------------------------------------------

    @property
    def tracked_until(self) -> int:
        """Last frame every live target has a result for (-1 without targets)."""
        if not self._groups:
            return -1
        return min(group.head for group in self._groups)

    @property
    def furthest_frame(self) -> int:
        """Last frame any target has a result for (-1 without targets)."""
        return max((target.last_frame for target in self.targets.values()), default=-1)

    def advance(self, frame_index: int) -> None:
        """Track every group whose head is the previous frame onto `frame_index`, then
        estimate the pose there if it is not known yet."""
        if not 0 < frame_index < self.frame_count:
            return
        due = [group for group in self._groups if group.head == frame_index - 1]
        if due:
            frame = self.frame(frame_index)
            started = time.perf_counter()
            for group in due:
                results = group.tracker.update(frame)
                group.head = frame_index
                for target_id, result in results.items():
                    self._store(self.targets[target_id], result, frame_index)
            self.frame_seconds[frame_index] = time.perf_counter() - started
        self._estimate_pose(frame_index)

    def track_to(self, frame_index: int, should_stop: Callable[[], bool] | None = None) -> None:
        """Track forward until every target has a result at `frame_index` (or `should_stop`)."""
        frame_index = min(frame_index, self.frame_count - 1)
        while self._groups and self.tracked_until < frame_index:
            if should_stop is not None and should_stop():
                return
            self.advance(self.tracked_until + 1)

    def results_at(self, frame_index: int) -> dict[str, TrackResult]:
        """Target id -> result at `frame_index`, for targets that have one."""
        return {
            target.id: target.results[frame_index]
            for target in self.targets.values()
            if frame_index in target.results
        }

    # -- localisation -------------------------------------------------------------------------

    def _drop_poses_from(self, frame_index: int) -> None:
        recorder = self._recording() if self.targets else None
        for index in [index for index in self.poses if index >= frame_index]:
            del self.poses[index]
            if recorder is not None:
                # Superseded in the recording too: re-estimated later, or left invalid.
                recorder.log_pose(discarded_pose(index))
        if self._localizer is not None and self._last_pose_frame >= frame_index:
            # The localiser keeps the previous pose as a continuity prior: start it afresh.
            self._localizer.reset()
            self._last_pose_frame = -1

    def _estimate_pose(self, frame_index: int) -> None:
        if self._localizer is None or frame_index in self.poses:
            return
        points: dict[str, tuple[float, float]] = {}
        confidences: dict[str, float] = {}
        aberrant: dict[str, bool] = {}
        for target in self.targets.values():
            result = target.results.get(frame_index)
            if target.landmark_id is None or result is None:
                continue
            points[target.landmark_id] = result.center
            confidences[target.landmark_id] = float(result.peak_score)
            aberrant[target.landmark_id] = bool(result.aberrant)
        if not points:
            return
        if frame_index != self._last_pose_frame + 1:
            self._localizer.reset()
        pose = self._localizer.estimate(frame_index, points, confidences, aberrant)
        self._last_pose_frame = frame_index
        self.poses[frame_index] = pose
        recorder = self._recording()
        if recorder is not None:
            recorder.log_pose(pose)

    def valid_positions(self) -> Iterator[tuple[int, np.ndarray]]:
        """(frame index, camera position) of the valid poses, in frame order."""
        for index in sorted(self.poses):
            pose = self.poses[index]
            if pose.valid:
                yield index, np.asarray(pose.position, dtype=np.float64)

    # -- resuming -----------------------------------------------------------------------------

    def restore(
        self,
        session: Session,
        state: Mapping[str, tuple[int, Box]],
        session_path: Path,
    ) -> int:
        """Continue a recorded session: its results and poses become this run's history (and
        are copied into this run's new recording), and each live target restarts from its last
        recorded box. Returns the frame to continue from (the earliest restart frame).

        Filters are not stored in a session, so a restarted target learns afresh from its last
        box; frames after each restart frame are tracked again when played.
        """
        if self.targets:
            raise InputError("restore a session into a fresh run only")
        self.resumed_from = session_path
        count = min(len(session.frame_indices), self.frame_count)
        for position, target_id in enumerate(session.targets):
            if target_id not in state:
                continue
            landmark_id = session.landmark_ids.get(target_id)
            if landmark_id is not None and (
                self.scene is None or landmark_id not in self.scene.landmark_ids
            ):
                landmark_id = None
            match = re.fullmatch(r"T(\d+)", target_id)
            number = int(match.group(1)) if match else position + 1
            target = Target(
                id=target_id,
                number=number,
                landmark_id=landmark_id,
                signals={name: np.full(self.frame_count, np.nan) for name in SIGNAL_NAMES},
            )
            self.targets[target_id] = target
            self._next_number = max(self._next_number, number + 1)
            boxes = session.tracks[target_id]
            signals = session.signals[target_id]
            for frame_index in range(count):
                box = boxes[frame_index]
                if not np.isfinite(box).all():
                    continue
                recorded = TrackResult(
                    frame_index=frame_index,
                    box=(float(box[0]), float(box[1]), float(box[2]), float(box[3])),
                    peak_score=float(session.scores[target_id][frame_index]),
                    response_map=None,
                    local_variation=None,
                    global_variation=float(signals["global_variation"][frame_index]),
                    theta_ref=float(signals["theta_ref"][frame_index]),
                    theta=float(signals["theta"][frame_index]),
                    aberrant=bool(session.aberrant[target_id][frame_index]),
                    scale_factor=float(signals["scale_factor"][frame_index]),
                    search_box=(float(box[0]), float(box[1]), float(box[2]), float(box[3])),
                )
                self._store(target, recorded, frame_index)
        self._restore_poses(session)
        restarts = []
        for target_id, (frame_index, box) in state.items():
            if target_id in self.targets and 0 <= frame_index < self.frame_count:
                target = self.targets[target_id]
                kept = target.results.get(frame_index)
                self._start_tracking(target, frame_index, box, kept=kept)
                restarts.append(frame_index)
        self._log_event("session_resumed", min(restarts, default=0), None, source=str(session_path))
        return min(restarts, default=0)

    def _restore_poses(self, session: Session) -> None:
        track = session.poses
        for row, frame_index in enumerate(track.frame_indices.tolist()):
            if not 0 <= frame_index < self.frame_count:
                continue
            valid = bool(track.valid[row])
            rotation = np.full((3, 3), np.nan)
            if valid:
                rotation = Rotation.from_quat(track.quaternions_xyzw[row]).as_matrix()
            pose = PoseEstimate(
                frame_index=frame_index,
                valid=valid,
                rotation=rotation,
                position=np.array(track.positions[row], dtype=np.float64),
                reprojection_errors=dict(track.reprojection_errors[row]),
                used_landmarks=tuple(track.used_landmarks[row]),
                reason=track.reasons[row],
                rms_error_px=float(track.rms_error_px[row]),
                position_std_m=float(track.position_std_m[row]),
            )
            self.poses[frame_index] = pose
            recorder = self._recording()
            if recorder is not None:
                recorder.log_pose(pose)


def discarded_result(frame_index: int) -> TrackResult:
    """A record saying a target has no result on `frame_index` (its box was redrawn earlier)."""
    nan = float("nan")
    return TrackResult(
        frame_index=frame_index,
        box=(nan, nan, nan, nan),
        peak_score=nan,
        response_map=None,
        local_variation=None,
        global_variation=nan,
        theta_ref=nan,
        theta=nan,
        aberrant=False,
        scale_factor=nan,
        search_box=(nan, nan, nan, nan),
    )


def discarded_pose(frame_index: int) -> PoseEstimate:
    """A record saying the pose of `frame_index` no longer holds (a box before it changed)."""
    return PoseEstimate(
        frame_index=frame_index,
        valid=False,
        rotation=np.full((3, 3), np.nan),
        position=np.full(3, np.nan),
        reprojection_errors={},
        used_landmarks=(),
        reason="discarded: a box was redrawn on an earlier frame",
    )
