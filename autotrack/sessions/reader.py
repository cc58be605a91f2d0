"""Reading a session file back, also one cut short by a crash (`open_session`)."""

from __future__ import annotations

import base64
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mcap.records import Attachment, Channel, Message, Metadata, Schema

import autotrack
from autotrack.errors import SessionError
from autotrack.hybrid.factory import TRUSTED
from autotrack.sessions.encoding import (
    DEFAULT_FPS,
    FORMAT_VERSION,
    SESSION_METADATA_NAME,
    box_tuple,
    dequantise_map,
    none_to_nan,
)
from autotrack.sessions.limits import DECODE_ERRORS, checked_frame_index
from autotrack.sessions.output import recording_in_progress
from autotrack.sessions.records import iter_records, scan_records
from autotrack.sessions.schemas import TargetStream, TargetTopic, Topics
from autotrack.sessions.session import PoseTrack, Session, SessionEvent

_SIGNAL_NAMES = ("theta_ref", "theta", "global_variation", "scale_factor")


class _SessionBuilder:
    """Accumulates decoded records (in file order) into a Session."""

    def __init__(self, load_maps: bool) -> None:
        self.load_maps = load_maps
        self.metadata: dict[str, str] | None = None
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.target_rows: dict[str, dict[int, dict[str, Any]]] = {}
        self.target_order: list[str] = []
        self.pose_quality: dict[int, dict[str, Any]] = {}
        self.pose_values: dict[int, dict[str, Any]] = {}
        self.events: list[SessionEvent] = []
        self.landmarks: dict[str, np.ndarray] = {}
        self.maps: dict[str, dict[str, dict[int, np.ndarray]]] = {
            "response": {},
            "local_variation": {},
        }
        self.last_boxes: dict[str, tuple[int, tuple[float, float, float, float]]] = {}
        self.message_count = 0
        self.image_count = 0
        self.first_publish: int | None = None
        self.last_publish: int | None = None
        self.scene_attachment: bytes | None = None

    def add(self, record: Any) -> None:
        if isinstance(record, Metadata) and record.name == SESSION_METADATA_NAME:
            self.metadata = dict(record.metadata)
        elif isinstance(record, Attachment) and self.scene_attachment is None:
            self.scene_attachment = bytes(record.data)
        elif isinstance(record, Schema):
            self.schemas[record.id] = record
        elif isinstance(record, Channel):
            self.channels[record.id] = record
        elif isinstance(record, Message):
            self._add_message(record)

    def _add_message(self, message: Message) -> None:
        channel = self.channels.get(message.channel_id)
        if channel is None:
            raise SessionError(f"message on unknown channel {message.channel_id}")
        self.message_count += 1
        if self.first_publish is None:
            self.first_publish = message.publish_time
        self.last_publish = message.publish_time
        topic = channel.topic
        target = TargetTopic.parse(topic)
        if target is not None:
            self._add_target_message(target, message)
        elif topic == Topics.POSE_QUALITY.name:
            quality = json.loads(message.data)
            checked_frame_index(quality["frame_index"])
            self.pose_quality[message.log_time] = quality
        elif topic == Topics.POSE.name:
            self.pose_values[message.log_time] = json.loads(message.data)["pose"]
        elif topic == Topics.EVENTS.name:
            self._add_event(json.loads(message.data))
        elif topic == Topics.LANDMARKS.name:
            self._add_landmarks(json.loads(message.data))
        elif topic == Topics.IMAGE.name:
            self.image_count += 1

    def _add_target_message(self, target: TargetTopic, message: Message) -> None:
        if not target.target_id.isprintable():
            raise SessionError(f"target id {target.target_id!r} holds control characters")
        if target.stream is TargetStream.SIGNALS:
            self._add_signals(target.target_id, json.loads(message.data))
        elif target.stream.value in self.maps and self.load_maps:
            image = json.loads(message.data)
            pixels = np.frombuffer(base64.b64decode(image["data"]), dtype=np.uint8)
            pixels = pixels.reshape(int(image["height"]), int(image["step"]))
            by_time = self.maps[target.stream.value].setdefault(target.target_id, {})
            by_time[message.log_time] = pixels[:, : int(image["width"])]

    def _add_landmarks(self, update: dict[str, Any]) -> None:
        for deletion in update.get("deletions", []):
            if deletion.get("type") == 1:
                self.landmarks.clear()
            else:
                self.landmarks.pop(str(deletion.get("id")), None)
        for entity in update.get("entities", []):
            if entity.get("spheres"):
                position = entity["spheres"][0]["pose"]["position"]
                self.landmarks[str(entity["id"])] = np.array(
                    [position["x"], position["y"], position["z"]], dtype=np.float64
                )

    def _add_signals(self, target_id: str, row: dict[str, Any]) -> None:
        if target_id not in self.target_rows:
            self.target_rows[target_id] = {}
            self.target_order.append(target_id)
        frame_index = checked_frame_index(row["frame_index"])
        self.target_rows[target_id][frame_index] = row  # a re-tracked frame: the later one wins
        box = box_tuple(row["box"])
        if all(math.isfinite(v) for v in box):
            self.last_boxes[target_id] = (frame_index, box)

    def _add_event(self, payload: dict[str, Any]) -> None:
        box = payload.get("box")
        event = SessionEvent(
            kind=str(payload["kind"]),
            frame_index=checked_frame_index(payload["frame_index"]),
            target_id=payload.get("target_id"),
            box=None if box is None else box_tuple(box),
            wall_time=float(payload["wall_time"]),
            extra=dict(payload.get("extra") or {}),
        )
        self.events.append(event)
        if event.target_id is None:
            return
        if event.kind == "box_deleted":
            self.last_boxes.pop(event.target_id, None)
        elif event.box is not None and all(math.isfinite(v) for v in event.box):
            self.last_boxes[event.target_id] = (event.frame_index, event.box)

    def build(
        self, path: Path, truncated: bool, bytes_read: int, file_size: int, being_recorded: bool
    ) -> Session:
        assert self.metadata is not None
        metadata: dict[str, Any] = dict(self.metadata)
        fps = float(metadata.get("fps", DEFAULT_FPS))
        if not (math.isfinite(fps) and fps > 0):
            raise SessionError(f"its frame rate {metadata.get('fps')!r} is not a positive number")
        metadata["fps"] = fps
        metadata["tracker_params"] = json.loads(metadata.get("tracker_params") or "{}")
        if not isinstance(metadata["tracker_params"], dict):
            raise SessionError("its tracker_params are not a JSON object")
        last_frames = [max(rows) for rows in self.target_rows.values() if rows]
        last_frames += [int(q["frame_index"]) for q in self.pose_quality.values()]
        count = max(last_frames) + 1 if last_frames else 0
        frame_indices = np.arange(count, dtype=np.int64)
        columns = {
            target_id: _TargetColumns.of(self.target_rows[target_id], count)
            for target_id in self.target_order
        }
        frame_of_time = {target_id: column.times for target_id, column in columns.items()}
        response_maps, local_maps = self._dequantised_maps(frame_of_time)
        return Session(
            path=path,
            format_version=int(metadata.get("format_version", FORMAT_VERSION)),
            metadata=metadata,
            truncated=truncated,
            fps=fps,
            targets=tuple(self.target_order),
            frame_indices=frame_indices,
            tracks={target_id: column.boxes for target_id, column in columns.items()},
            scores={target_id: column.scores for target_id, column in columns.items()},
            aberrant={target_id: column.aberrant for target_id, column in columns.items()},
            signals={target_id: column.signals for target_id, column in columns.items()},
            landmark_ids={target_id: column.landmark_id for target_id, column in columns.items()},
            search_boxes={target_id: column.search_boxes for target_id, column in columns.items()},
            trusted={target_id: column.trusted for target_id, column in columns.items()},
            poses=self._pose_track(),
            events=tuple(self.events),
            landmarks=dict(self.landmarks),
            last_boxes=dict(self.last_boxes),
            response_maps=response_maps,
            local_variation_maps=local_maps,
            message_count=self.message_count,
            image_count=self.image_count,
            wall_time_span_s=(
                (self.last_publish - self.first_publish) / 1e9
                if self.first_publish is not None and self.last_publish is not None
                else 0.0
            ),
            bytes_read=bytes_read,
            file_size=file_size,
            scene_attachment=self.scene_attachment,
            partial_frame=self._partial_last_frame() if truncated else None,
            being_recorded=being_recorded,
        )

    def _partial_last_frame(self) -> int | None:
        """The last frame of a file cut short, when a crash left only part of its records: a
        target recorded on the previous frame (and not deleted) or the previous frame's pose is
        missing there. Each target's and each pose's records are written in one piece, so a
        frame is cut between them, never inside one."""
        pose_frames = {int(quality["frame_index"]) for quality in self.pose_quality.values()}
        frames = set(pose_frames).union(*(set(rows) for rows in self.target_rows.values()))
        if len(frames) < 2:
            return None
        last = max(frames)
        previous = max(frames - {last})
        deleted = {event.target_id for event in self.events if event.kind == "box_deleted"}
        target_missing = any(
            previous in rows and last not in rows and target_id not in deleted
            for target_id, rows in self.target_rows.items()
        )
        pose_missing = previous in pose_frames and last not in pose_frames
        return last if target_missing or pose_missing else None

    def _dequantised_maps(
        self, frame_of_time: dict[str, dict[int, tuple[int, Any, Any]]]
    ) -> tuple[dict[str, dict[int, np.ndarray]], dict[str, dict[int, np.ndarray]]]:
        result: dict[str, dict[str, dict[int, np.ndarray]]] = {
            "response": {},
            "local_variation": {},
        }
        for kind, per_target in self.maps.items():
            range_index = 1 if kind == "response" else 2
            for target_id, by_time in per_target.items():
                times = frame_of_time.get(target_id, {})
                for time_ns, pixels in by_time.items():
                    if time_ns not in times or times[time_ns][range_index] is None:
                        continue  # cut off before its signals message: range unknown
                    frame_index = times[time_ns][0]
                    lo, hi = (none_to_nan(v) for v in times[time_ns][range_index])
                    result[kind].setdefault(target_id, {})[frame_index] = dequantise_map(
                        pixels, lo, hi
                    )
        return result["response"], result["local_variation"]

    def _pose_track(self) -> PoseTrack:
        ordered = sorted(self.pose_quality.items(), key=lambda item: item[1]["frame_index"])
        count = len(ordered)
        positions = np.full((count, 3), np.nan)
        quaternions = np.full((count, 4), np.nan)
        valid = np.zeros(count, dtype=bool)
        for row, (time_ns, quality) in enumerate(ordered):
            pose = self.pose_values.get(time_ns)
            if quality.get("valid") and pose is not None:
                valid[row] = True
                position, orientation = pose["position"], pose["orientation"]
                positions[row] = [position["x"], position["y"], position["z"]]
                quaternions[row] = [orientation[k] for k in ("x", "y", "z", "w")]
        return PoseTrack(
            frame_indices=np.array([q["frame_index"] for _, q in ordered], dtype=np.int64),
            valid=valid,
            positions=positions,
            quaternions_xyzw=quaternions,
            reprojection_errors=tuple(
                {k: none_to_nan(v) for k, v in (q.get("reprojection_errors") or {}).items()}
                for _, q in ordered
            ),
            mean_reprojection_error=np.array(
                [none_to_nan(q.get("mean_reprojection_error")) for _, q in ordered],
                dtype=np.float64,
            ),
            rms_error_px=np.array(
                [none_to_nan(q.get("rms_error_px")) for _, q in ordered], dtype=np.float64
            ),
            position_std_m=np.array(
                [none_to_nan(q.get("position_std_m")) for _, q in ordered], dtype=np.float64
            ),
            used_landmarks=tuple(
                tuple(str(v) for v in (q.get("used_landmarks") or ())) for _, q in ordered
            ),
            reasons=tuple(q.get("reason") or "" for _, q in ordered),
        )


@dataclass(frozen=True)
class _TargetColumns:
    """One target's records as arrays over the frames (row i = frame i)."""

    boxes: np.ndarray
    scores: np.ndarray
    aberrant: np.ndarray
    signals: dict[str, np.ndarray]
    search_boxes: np.ndarray
    landmark_id: str | None
    times: dict[int, tuple[int, Any, Any]]
    """Log time -> (frame index, response range, local-variation range), to match the maps."""
    trusted: np.ndarray
    """The hybrid's trusted tracker per frame ('' where none is recorded)."""

    @classmethod
    def of(cls, rows: Mapping[int, dict[str, Any]], count: int) -> _TargetColumns:
        boxes = np.full((count, 4), np.nan)
        search_boxes = np.full((count, 4), np.nan)
        scores = np.full(count, np.nan)
        aberrant = np.zeros(count, dtype=bool)
        trusted = np.full(count, "", dtype=f"<U{max(map(len, TRUSTED))}")
        signals = {name: np.full(count, np.nan) for name in _SIGNAL_NAMES}
        times: dict[int, tuple[int, Any, Any]] = {}
        landmark_id = None
        for frame_index, row in rows.items():
            boxes[frame_index] = [none_to_nan(v) for v in row["box"]]
            if row.get("search_box") is not None:
                search_boxes[frame_index] = [none_to_nan(v) for v in row["search_box"]]
            scores[frame_index] = none_to_nan(row.get("peak_score"))
            aberrant[frame_index] = bool(row.get("aberrant"))
            if row.get("trusted") in TRUSTED:
                trusted[frame_index] = row["trusted"]
            for name in _SIGNAL_NAMES:
                signals[name][frame_index] = none_to_nan(row.get(name))
            stamp = row["timestamp"]
            time_ns = int(stamp["sec"]) * 1_000_000_000 + int(stamp["nsec"])
            times[time_ns] = (
                frame_index,
                row.get("response_range"),
                row.get("local_variation_range"),
            )
            landmark_id = row.get("landmark_id")
        return cls(boxes, scores, aberrant, signals, search_boxes, landmark_id, times, trusted)


def open_session(path: str | Path, *, load_maps: bool = False) -> Session:
    """Read a session file, also one cut short by a crash (`Session.truncated`).

    load_maps: also decode the response and local-variation maps (slower, more memory).
    Raises SessionError for a missing, non-MCAP, corrupted or newer-format file.
    """
    path = Path(path)
    name = str(path)
    try:
        handle = open(path, "rb")  # noqa: SIM115 - closed below
    except FileNotFoundError as error:
        raise SessionError(f"session file {name} does not exist") from error
    except OSError as error:
        raise SessionError(f"cannot open session file {name}: {error}") from error
    with handle:
        size = os.fstat(handle.fileno()).st_size
        if size == 0:
            raise SessionError(f"{name} is empty: not an MCAP file")
        limit, complete = scan_records(handle, size, name)
        being_recorded = not complete and recording_in_progress(handle)
        builder = _SessionBuilder(load_maps)
        try:
            for record in iter_records(handle, limit):
                builder.add(record)
                if isinstance(record, Metadata) and record.name == SESSION_METADATA_NAME:
                    _check_version(builder.metadata or {}, name)
        except _NewerFormatError:
            raise
        except SessionError as error:
            raise SessionError(f"{name} is corrupted: {error}") from error
        except DECODE_ERRORS as error:
            raise SessionError(
                f"{name} is corrupted ({type(error).__name__}: {error}); "
                "it cannot be read past this point"
            ) from error
    if builder.metadata is None and not complete:
        raise SessionError(
            f"{name} was cut short before its session metadata was written: nothing to read"
        )
    if builder.metadata is None:
        raise SessionError(
            f"{name} is an MCAP file but not an AutoTrack session "
            f"(no '{SESSION_METADATA_NAME}' metadata record)"
        )
    try:
        return builder.build(
            path,
            truncated=not complete,
            bytes_read=limit,
            file_size=size,
            being_recorded=being_recorded,
        )
    except SessionError as error:
        raise SessionError(f"{name} is corrupted: {error}") from error
    except DECODE_ERRORS as error:
        raise SessionError(f"{name} is corrupted ({type(error).__name__}: {error})") from error


def _check_version(metadata: Mapping[str, str], name: str) -> None:
    try:
        version = int(metadata.get("format_version", ""))
    except ValueError as error:
        raise SessionError(
            f"{name}: session format version {metadata.get('format_version')!r} is not a number"
        ) from error
    if version > FORMAT_VERSION:
        raise _NewerFormatError(
            f"{name} was written in session format version {version} by autotrack-studio "
            f"{metadata.get('package_version', '?')}; this autotrack-studio "
            f"({autotrack.__version__}) reads format versions up to {FORMAT_VERSION}: "
            "upgrade autotrack-studio to open it"
        )


class _NewerFormatError(SessionError):
    """Raised for a session written by a newer format version (never reported as corruption)."""
