"""A session read back: per-target arrays, poses, events, and the typed per-frame outcomes
(`TrackResult`, `PoseEstimate`) a pipeline resumes from."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autotrack.errors import SessionError
from autotrack.hybrid.factory import with_trusted
from autotrack.params import TrackerParams
from autotrack.result import PoseEstimate, TrackResult
from autotrack.sessions.metadata import recorded_path

Box = tuple[float, float, float, float]


@dataclass(frozen=True)
class SessionEvent:
    """One recorded user edit or session event."""

    kind: str
    frame_index: int
    target_id: str | None
    box: tuple[float, float, float, float] | None
    wall_time: float
    """Unix time (seconds) at which the event was recorded."""
    extra: dict[str, Any]


@dataclass(frozen=True)
class PoseTrack:
    """Camera poses, one row per frame with a pose record, by frame index."""

    frame_indices: np.ndarray
    """(M,) int64 frame indices."""
    valid: np.ndarray
    """(M,) bool."""
    positions: np.ndarray
    """(M, 3) camera position in the world frame; NaN where not valid."""
    quaternions_xyzw: np.ndarray
    """(M, 4) camera-to-world rotation (x, y, z, w); NaN where not valid."""
    reprojection_errors: tuple[dict[str, float], ...]
    """Per frame: landmark id -> reprojection error (pixels)."""
    mean_reprojection_error: np.ndarray
    """(M,) mean reprojection error (pixels); NaN when none."""
    rms_error_px: np.ndarray
    """(M,) RMS reprojection error over the landmarks used (pixels); NaN when not given."""
    position_std_m: np.ndarray
    """(M,) predicted 1-sigma position uncertainty (metres); NaN when not given."""
    used_landmarks: tuple[tuple[str, ...], ...]
    """Per frame: the landmarks the pose was solved from."""
    reasons: tuple[str, ...]
    """Per frame: why the pose is not trusted ("" when valid or not given)."""


@dataclass(frozen=True)
class Session:
    """A session read back from its MCAP file (possibly cut short by a crash).

    Per-target arrays are indexed by frame: row i is frame i (`frame_indices` = 0..last recorded
    frame), NaN (False for `aberrant`) where the target has no result.
    """

    path: Path
    format_version: int
    metadata: dict[str, Any]
    """The session metadata record; `tracker_params` is decoded to a dict, `fps` to a float."""
    truncated: bool
    """True when the file has no valid end (the recorder did not close it: crash, kill, copy cut
    short); everything before the cut was read."""
    fps: float
    targets: tuple[str, ...]
    frame_indices: np.ndarray
    tracks: dict[str, np.ndarray]
    """Target id -> (N, 4) boxes (x, y, w, h), 0-based pixels."""
    scores: dict[str, np.ndarray]
    """Target id -> (N,) peak response score."""
    aberrant: dict[str, np.ndarray]
    """Target id -> (N,) bool aberrance flag."""
    signals: dict[str, dict[str, np.ndarray]]
    """Target id -> {theta_ref, theta, global_variation, scale_factor} -> (N,)."""
    landmark_ids: dict[str, str | None]
    """Target id -> id of the scene landmark it tracks (last recorded), or None."""
    poses: PoseTrack
    events: tuple[SessionEvent, ...]
    landmarks: dict[str, np.ndarray]
    """Landmark id -> (3,) world position, from the last /landmarks update."""
    last_boxes: dict[str, tuple[int, tuple[float, float, float, float]]]
    """Target id -> (frame index, box) of its latest record or box edit; deleted targets are
    absent."""
    response_maps: dict[str, dict[int, np.ndarray]]
    """Target id -> frame index -> de-quantised response map (only with load_maps=True)."""
    local_variation_maps: dict[str, dict[int, np.ndarray]]
    """Target id -> frame index -> de-quantised local variation map (only with load_maps=True)."""
    message_count: int
    image_count: int
    """Number of embedded video frames."""
    wall_time_span_s: float
    """Seconds of wall-clock time between the first and the last recorded message."""
    bytes_read: int
    """Bytes of the file that hold complete records (the rest was cut off)."""
    file_size: int
    search_boxes: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    """Target id -> (N, 4) search regions (x, y, w, h) of the recorded results; NaN where none."""
    trusted: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    """Target id -> (N,) str: which tracker the hybrid trusted on each frame (`both`, `filter`,
    `siamese`: `autotrack.hybrid.factory.TRUSTED`); '' where none is recorded (another
    tracker, or no result)."""
    scene_attachment: bytes | None = field(default=None, repr=False)
    """Contents of the scene file recorded with the session, if any."""
    being_recorded: bool = False
    """A recorder holds the file's write lock: it is still being written (not cut short; the
    end comes when the recording closes). `autotrack.sessions.output.recording_in_progress`."""
    partial_frame: int | None = None
    """In a file cut short: its last frame when only part of that frame's records reached the
    file (a target or the pose recorded on the frame before is missing there); its records are
    kept, but it is not counted in `frame_count`."""

    @property
    def source(self) -> str:
        """What was tracked, as recorded (the sequence path, exactly as given)."""
        return recorded_path(self.metadata, "source")

    @property
    def recorded_live(self) -> bool:
        """The frames came from a live source, which cannot be replayed: the session is looked
        through on its embedded frames. (Sessions written before the `live_source` marker:
        those that embed frames, which only live runs did then.)"""
        marker = self.metadata.get("live_source")
        return marker == "true" if marker is not None else self.image_count > 0

    @property
    def scene_path(self) -> str | None:
        """The scene file the session was recorded with, as recorded (None: no scene)."""
        return recorded_path(self.metadata, "scene_path") or None

    @property
    def frame_count(self) -> int:
        """Number of complete frames with at least one target result (`partial_frame`, a
        frame only partly written when the recording was cut, is not counted)."""
        if not self.tracks:
            return 0
        has_box = np.zeros(len(self.frame_indices), dtype=bool)
        for boxes in self.tracks.values():
            has_box |= np.isfinite(boxes).all(axis=1)
        if self.partial_frame is not None and self.partial_frame < has_box.size:
            has_box[self.partial_frame] = False
        return int(has_box.sum())

    @property
    def deleted_targets(self) -> frozenset[str]:
        """Targets whose last box edit deleted them (and that were not drawn again)."""
        deleted = {e.target_id for e in self.events if e.kind == "box_deleted" and e.target_id}
        return frozenset(t for t in deleted if t not in self.last_boxes)

    @property
    def exported_targets(self) -> tuple[str, ...]:
        """Targets that exports write: every recorded target except deleted ones."""
        return tuple(t for t in self.targets if t not in self.deleted_targets)

    @property
    def duration_s(self) -> float:
        """Video time covered by the recorded frames (seconds at the session's fps)."""
        return len(self.frame_indices) / self.fps

    @property
    def tracker_name(self) -> str:
        """The recorded tracker (`nanotrack`, `hybrid` or an AutoTrack preset; a session
        recorded before trackers were named: the preset its parameters describe)."""
        return str(self.metadata.get("tracker") or "") or self.tracker_params().name

    def tracker_params(self) -> TrackerParams:
        """The recorded tracker parameters as TrackerParams (to resume tracking)."""
        recorded = dict(self.metadata.get("tracker_params") or {})
        known = {f.name for f in dataclasses.fields(TrackerParams)}
        unknown = sorted(set(recorded) - known)
        if unknown:
            raise SessionError(
                f"{self.path.name}: tracker parameters {', '.join(unknown)} are unknown to this "
                "version of autotrack-studio"
            )
        return TrackerParams(**recorded)

    def recorded_targets(self) -> dict[str, RecordedTarget]:
        """Every target that is not deleted, with its recorded results (maps are not recorded
        in full, so results carry none; a hybrid's are `HybridResult`s saying whom it trusted)
        and the box to resume it from."""
        targets = {}
        for target_id in self.exported_targets:
            boxes = self.tracks[target_id]
            signals = self.signals[target_id]
            results = {}
            trusted = self.trusted.get(target_id)
            for frame_index in np.flatnonzero(np.isfinite(boxes).all(axis=1)).tolist():
                search = self.search_boxes.get(target_id)
                search_box = None if search is None else search[frame_index]
                result = TrackResult(
                    frame_index=frame_index,
                    box=_box(boxes[frame_index]),
                    peak_score=float(self.scores[target_id][frame_index]),
                    response_map=None,
                    local_variation=None,
                    global_variation=float(signals["global_variation"][frame_index]),
                    theta_ref=float(signals["theta_ref"][frame_index]),
                    theta=float(signals["theta"][frame_index]),
                    aberrant=bool(self.aberrant[target_id][frame_index]),
                    scale_factor=float(signals["scale_factor"][frame_index]),
                    search_box=None
                    if search_box is None or not np.isfinite(search_box).all()
                    else _box(search_box),
                )
                if trusted is not None and trusted[frame_index]:
                    result = with_trusted(result, str(trusted[frame_index]))
                results[frame_index] = result
            targets[target_id] = RecordedTarget(
                id=target_id,
                landmark_id=self.landmark_ids.get(target_id),
                results=results,
                last_box=self.last_boxes.get(target_id),
            )
        return targets

    def pose_estimates(self) -> dict[int, PoseEstimate]:
        """Frame index -> the recorded camera pose (rotation from the recorded quaternion)."""
        from scipy.spatial.transform import Rotation  # scipy.spatial loads on first use (~0.4 s)

        track = self.poses
        estimates = {}
        for row, frame_index in enumerate(track.frame_indices.tolist()):
            valid = bool(track.valid[row])
            rotation = np.full((3, 3), np.nan)
            if valid:
                rotation = Rotation.from_quat(track.quaternions_xyzw[row]).as_matrix()
            estimates[frame_index] = PoseEstimate(
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
        return estimates


@dataclass(frozen=True)
class RecordedTarget:
    """One target of a session, as a pipeline resumes it."""

    id: str
    landmark_id: str | None
    """The scene landmark it localises (last recorded), or None."""
    results: dict[int, TrackResult]
    """Frame index -> recorded result (no maps)."""
    last_box: tuple[int, Box] | None
    """(frame index, box) of its latest record or box edit: where tracking resumes."""


def _box(values: np.ndarray) -> Box:
    x, y, w, h = (float(v) for v in values)
    return (x, y, w, h)
