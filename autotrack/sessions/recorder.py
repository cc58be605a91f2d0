"""Sessions: every tracked frame, pose and user edit recorded to one MCAP file, and read back.

A session file is written incrementally while frames are processed, so annotation and tracking
work survives a crash, and it opens in Foxglove with no plugin (well-known schemas, JSON
encoding). Layout, topics and the map quantisation are described in docs/sessions.md.

Crash safety: messages are gathered in a zstd-compressed MCAP chunk that is closed and handed to
the operating system (`mcap.writer.Writer.flush`, then the file object's flush) as soon as its
oldest message is `flush_interval` seconds old, by the next write or, when the recorder is idle,
by a background timer. User edits are flushed at once. A `kill -9` therefore loses at most the
last `flush_interval` (1 s) of records; `open_session` reads everything before the cut.
"""

from __future__ import annotations

import base64
import dataclasses
import io
import json
import math
import os
import re
import struct
import threading
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import Any, BinaryIO, Protocol

import mcap
import numpy as np
import zstandard
from mcap.exceptions import EndOfFile, McapError
from mcap.records import Attachment, Channel, DataEnd, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap.writer import CompressionType, Writer

import autotrack
from autotrack.errors import SessionError
from autotrack.params import TrackerParams
from autotrack.result import TrackResult
from autotrack.sessions import schemas as foxglove

FORMAT_VERSION = 1
"""Version of the session layout this package writes and the newest it reads."""
SESSION_METADATA_NAME = "autotrack.session"
"""Name of the MCAP metadata record that marks a file as an AutoTrack session."""
DEFAULT_FPS = 10.0
"""Frame rate used for log times when the source does not give one (frames per second)."""
DEFAULT_FLUSH_INTERVAL_S = 1.0
"""Longest time a recorded message waits in memory before it reaches the OS (seconds)."""
WORLD_FRAME = "world"
CAMERA_FRAME = "camera"
TOPIC_POSE = "/camera/pose"
TOPIC_TF = "/tf"
TOPIC_POSE_QUALITY = "/camera/pose_quality"
TOPIC_LANDMARKS = "/landmarks"
TOPIC_EVENTS = "/events"
TOPIC_IMAGE = "/camera/image"

_MCAP_MAGIC = b"\x89MCAP0\r\n"
_TARGET_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
_EVENT_KIND = re.compile(r"^[a-z][a-z0-9_]{0,63}$")
_TARGET_TOPIC = re.compile(r"^/targets/([^/]+)/(box|signals|response|local_variation)$")
_OPCODE_FOOTER = 0x02
_OPCODE_DATA_END = 0x0F
_KNOWN_OPCODES = frozenset(range(0x01, 0x10))
_PALETTE: tuple[tuple[float, float, float, float], ...] = (
    (0.12, 0.47, 0.71, 1.0),
    (0.17, 0.63, 0.17, 1.0),
    (1.0, 0.5, 0.05, 1.0),
    (0.58, 0.4, 0.74, 1.0),
    (0.09, 0.75, 0.81, 1.0),
    (0.74, 0.74, 0.13, 1.0),
    (0.89, 0.47, 0.76, 1.0),
    (0.55, 0.34, 0.29, 1.0),
)
_ABERRANT_RGBA = (0.84, 0.15, 0.16, 1.0)
_SIGNAL_NAMES = ("theta_ref", "theta", "global_variation", "scale_factor")

_NULLABLE_NUMBER = {"type": ["number", "null"]}
_TIME = foxglove.TIME_JSON_SCHEMA
_BOX = {"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4}
_NULLABLE_BOX = {"type": ["array", "null"], "items": {"type": "number"}, "minItems": 4}
_RANGE = {"type": ["array", "null"], "items": {"type": "number"}, "minItems": 2, "maxItems": 2}

TARGET_SIGNALS_SCHEMA: dict[str, Any] = {
    "title": "autotrack.TargetSignals",
    "description": "One target in one frame: the tracker's box and the signals inside the filter. "
    "Boxes are (x, y, w, h) in 0-based pixels. A null number is NaN (undefined in this frame). "
    "response_range / local_variation_range: [lo, hi] of the map before mono8 quantisation "
    "(value = lo + q / 255 * (hi - lo)); null when the map was not recorded.",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame_index": {"type": "integer", "minimum": 0},
        "target_id": {"type": "string"},
        "box": _BOX,
        "peak_score": _NULLABLE_NUMBER,
        "aberrant": {"type": "boolean"},
        "theta_ref": _NULLABLE_NUMBER,
        "theta": _NULLABLE_NUMBER,
        "global_variation": _NULLABLE_NUMBER,
        "scale_factor": _NULLABLE_NUMBER,
        "search_box": _NULLABLE_BOX,
        "landmark_id": {"type": ["string", "null"]},
        "response_range": _RANGE,
        "local_variation_range": _RANGE,
    },
    "required": ["timestamp", "frame_index", "target_id", "box", "aberrant"],
}
POSE_QUALITY_SCHEMA: dict[str, Any] = {
    "title": "autotrack.PoseQuality",
    "description": "Validity of the camera pose of one frame and the reprojection error (pixels) "
    "of each landmark used; the pose itself is on /camera/pose and /tf when valid.",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame_index": {"type": "integer", "minimum": 0},
        "valid": {"type": "boolean"},
        "reason": {"type": "string"},
        "reprojection_errors": {"type": "object", "additionalProperties": _NULLABLE_NUMBER},
        "mean_reprojection_error": _NULLABLE_NUMBER,
        "used_landmarks": {"type": ["array", "null"], "items": {"type": "string"}},
        "rms_error_px": _NULLABLE_NUMBER,
        "position_std_m": _NULLABLE_NUMBER,
    },
    "required": ["timestamp", "frame_index", "valid"],
}
SESSION_EVENT_SCHEMA: dict[str, Any] = {
    "title": "autotrack.SessionEvent",
    "description": "A user edit or session event (box drawn, corrected, deleted, ...), with the "
    "frame it applies to, the wall-clock time (Unix seconds) and kind-specific extras.",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "kind": {"type": "string"},
        "frame_index": {"type": "integer", "minimum": 0},
        "target_id": {"type": ["string", "null"]},
        "box": _NULLABLE_BOX,
        "wall_time": {"type": "number"},
        "extra": {"type": "object"},
    },
    "required": ["timestamp", "kind", "frame_index", "wall_time"],
}

SCHEMAS: dict[str, bytes] = {
    **{
        schema.full_name: foxglove.schema_bytes(schema)
        for schema in (
            foxglove.IMAGE_ANNOTATIONS,
            foxglove.RAW_IMAGE,
            foxglove.COMPRESSED_IMAGE,
            foxglove.POSE_IN_FRAME,
            foxglove.FRAME_TRANSFORM,
            foxglove.SCENE_UPDATE,
        )
    },
    **{
        schema["title"]: json.dumps(schema, separators=(",", ":")).encode("utf-8")
        for schema in (TARGET_SIGNALS_SCHEMA, POSE_QUALITY_SCHEMA, SESSION_EVENT_SCHEMA)
    },
}
"""Schema name -> JSON Schema document of every channel we write (schema encoding "jsonschema",
message encoding "json")."""


class PoseLike(Protocol):
    """What the recorder reads from a camera pose (autotrack.localize.PoseEstimate)."""

    frame_index: int
    valid: bool
    position: Any
    reprojection_errors: Mapping[str, float]
    reason: str | None

    def quaternion_xyzw(self) -> Any: ...


# --- small pure helpers -----------------------------------------------------------------------


def frame_time_ns(frame_index: int, fps: float) -> int:
    """Log time of a frame: its time in the video, frame_index / fps, in nanoseconds."""
    if int(frame_index) < 0:
        raise SessionError(f"frame index must be 0 or more, got {frame_index}")
    return round(int(frame_index) * 1e9 / float(fps))


def quantise_map(values: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Min-max quantise a float map to uint8: q = round(255 * (v - lo) / (hi - lo)).

    Returns (q, lo, hi). A constant map gives q = 0 and lo = hi. Non-finite values map to 0.
    """
    values = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(values)
    if not finite.any():
        return np.zeros(values.shape, dtype=np.uint8), math.nan, math.nan
    lo = float(values[finite].min())
    hi = float(values[finite].max())
    span = hi - lo
    if span <= 0.0:
        return np.zeros(values.shape, dtype=np.uint8), lo, hi
    scaled = np.where(finite, (values - lo) / span * 255.0, 0.0)
    return np.clip(np.rint(scaled), 0, 255).astype(np.uint8), lo, hi


def dequantise_map(quantised: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Inverse of `quantise_map` (to within (hi - lo) / 510): v = lo + q / 255 * (hi - lo)."""
    q = np.asarray(quantised, dtype=np.float32)
    return (np.float32(lo) + q / np.float32(255.0) * np.float32(hi - lo)).astype(np.float32)


def _finite_or_none(value: Any) -> float | None:
    if value is None:
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def _none_to_nan(value: Any) -> float:
    return math.nan if value is None else float(value)


def _jsonable(value: Any) -> Any:
    """Plain JSON data from numpy scalars/arrays, tuples and NaN (-> null)."""
    if isinstance(value, Mapping):
        return {str(key): _jsonable(item) for key, item in value.items()}
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, list | tuple | set | frozenset):
        return [_jsonable(item) for item in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return _finite_or_none(value)
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, Path):
        return str(value)
    raise SessionError(f"cannot record a value of type {type(value).__name__} ({value!r}) in JSON")


def _encode(payload: Mapping[str, Any]) -> bytes:
    return json.dumps(payload, separators=(",", ":"), allow_nan=False).encode("utf-8")


def _box_tuple(values: Sequence[float | None]) -> tuple[float, float, float, float]:
    x, y, w, h = (_none_to_nan(v) for v in values)
    return (x, y, w, h)


def _box_list(box: Sequence[float]) -> list[float]:
    values = [float(v) for v in box]
    if len(values) != 4:
        raise SessionError(f"a box needs 4 numbers (x, y, w, h), got {len(values)}")
    return values


def _check_target_id(target_id: str) -> str:
    target_id = str(target_id)
    if not _TARGET_ID.match(target_id):
        raise SessionError(
            f"target id {target_id!r} cannot be recorded: use 1-64 letters, digits, '_', '-' "
            "or '.', starting with a letter or digit"
        )
    return target_id


def _package_version() -> str:
    return autotrack.__version__


def _params_dict(tracker_params: TrackerParams | Mapping[str, Any]) -> dict[str, Any]:
    if isinstance(tracker_params, TrackerParams):
        return _jsonable(dataclasses.asdict(tracker_params))
    if isinstance(tracker_params, Mapping):
        return _jsonable(dict(tracker_params))
    raise SessionError(
        f"tracker_params must be TrackerParams or a dict, got {type(tracker_params).__name__}"
    )


def _safe_name(name: str) -> str:
    cleaned = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._-")
    return cleaned[:80] or "session"


def _landmark_positions(scene: Any) -> list[tuple[str, np.ndarray]]:
    """(id, position) pairs from a Scene, a mapping id -> position, or objects with .id/.position."""
    landmarks = getattr(scene, "landmarks", scene)
    if isinstance(landmarks, Mapping):
        items: Iterable[tuple[Any, Any]] = landmarks.items()
    else:
        items = (
            (getattr(item, "id", getattr(item, "landmark_id", None)), item.position)
            for item in landmarks
        )
    result = []
    for landmark_id, position in items:
        point = np.asarray(position, dtype=np.float64).reshape(-1)
        if landmark_id is None or point.shape != (3,) or not np.isfinite(point).all():
            raise SessionError(f"landmark {landmark_id!r} needs an id and a finite 3-D position")
        result.append((str(landmark_id), point))
    return result


# --- recording --------------------------------------------------------------------------------


class SessionRecorder:
    """Writes one session to a new MCAP file, incrementally and crash-safely.

    Use as a context manager, or call `close()`; the file is complete (summary and footer) only
    after `close()`, but everything flushed before a crash can be read back.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        source: str,
        tracker_params: TrackerParams | Mapping[str, Any],
        scene_path: str | Path | None = None,
        fps: float | None = None,
        embed_frames: bool = False,
        record_maps: bool = True,
        jpeg_quality: int = 90,
        flush_interval: float = DEFAULT_FLUSH_INTERVAL_S,
        fsync: bool = False,
        resumed_from: str | Path | None = None,
    ) -> None:
        """Create the session file at exactly `path`; an existing file is never overwritten.

        source: what was tracked (sequence folder, video file, camera name).
        tracker_params: the parameters of the tracker(s) of this session.
        scene_path: localisation scene file; recorded by name and embedded as an attachment.
        fps: frame rate of the source; log times are frame_index / fps (DEFAULT_FPS if None).
        embed_frames: record the video frames as JPEG (`log_frame`); large, off by default.
        record_maps: record the response and local-variation maps (mono8, ~2.5 kB each).
        jpeg_quality: JPEG quality of embedded frames (0-100).
        flush_interval: longest time (s) a message waits in memory before reaching the OS.
        fsync: also fsync the file at each flush (survives power loss, slower).
        resumed_from: the session this one continues, if any.
        """
        if fps is not None and not (math.isfinite(fps) and fps > 0):
            raise SessionError(f"fps must be a positive number, got {fps}")
        if not flush_interval > 0:
            raise SessionError(f"flush_interval must be positive, got {flush_interval}")
        if not hasattr(Writer, "flush"):
            raise SessionError("recording sessions needs mcap>=1.6 (Writer.flush); upgrade mcap")
        self.path = Path(path)
        self.fps = float(fps) if fps is not None else DEFAULT_FPS
        self.embed_frames = bool(embed_frames)
        self.record_maps = bool(record_maps)
        self.jpeg_quality = int(jpeg_quality)
        self.flush_interval = float(flush_interval)
        self._fsync = bool(fsync)
        params = _params_dict(tracker_params)
        scene_bytes = None
        if scene_path is not None:
            try:
                scene_bytes = Path(scene_path).read_bytes()
            except OSError as error:
                raise SessionError(f"cannot read scene file {scene_path}: {error}") from error
        try:
            self._file: BinaryIO = open(self.path, "xb")  # noqa: SIM115 - closed in close()
        except FileExistsError as error:
            raise _SessionFileExistsError(
                f"{self.path} already exists; session files are never overwritten"
            ) from error
        except OSError as error:
            raise SessionError(f"cannot create session file {self.path}: {error}") from error

        self._lock = threading.Lock()
        self._writer = Writer(
            self._file, compression=CompressionType.ZSTD, enable_crcs=True, enable_data_crcs=True
        )
        self._schema_ids: dict[str, int] = {}
        self._channel_ids: dict[str, int] = {}
        self._target_colours: dict[str, tuple[float, float, float, float]] = {}
        self._sequence = 0
        self._pending_since: float | None = None
        self._pending_max_frame: int | None = None
        self._saved_frame_index: int | None = None
        self._flush_error: BaseException | None = None
        self._closed = False
        created = datetime.now(UTC).isoformat(timespec="seconds")
        self.metadata: dict[str, str] = {
            "format_version": str(FORMAT_VERSION),
            "package_version": _package_version(),
            "mcap_version": getattr(mcap, "__version__", "unknown"),
            "created_utc": created,
            "source": str(source),
            "fps": repr(self.fps),
            "fps_given": "true" if fps is not None else "false",
            "tracker_params": json.dumps(params, sort_keys=True),
            "scene_path": str(scene_path) if scene_path is not None else "",
            "embed_frames": "true" if self.embed_frames else "false",
            "record_maps": "true" if self.record_maps else "false",
            "map_encoding": "mono8, min-max per map: value = lo + q / 255 * (hi - lo), "
            "[lo, hi] in the target's signals message",
            "flush_interval_s": repr(self.flush_interval),
            "resumed_from": str(resumed_from) if resumed_from is not None else "",
        }
        try:
            self._writer.start(profile="", library=f"autotrack-studio {_package_version()}")
            self._writer.add_metadata(SESSION_METADATA_NAME, self.metadata)
            if scene_bytes is not None:
                now = time.time_ns()
                self._writer.add_attachment(
                    now, 0, Path(scene_path).name, "application/octet-stream", scene_bytes
                )
            self._writer.flush()
        except OSError as error:
            self._file.close()
            raise SessionError(f"cannot write session file {self.path}: {error}") from error
        self._stop = threading.Event()
        self._flusher = threading.Thread(
            target=self._flush_loop, name=f"session-flush-{self.path.name}", daemon=True
        )
        self._flusher.start()

    @classmethod
    def create(
        cls,
        directory: str | Path,
        *,
        source: str,
        tracker_params: TrackerParams | Mapping[str, Any],
        name: str | None = None,
        **options: Any,
    ) -> SessionRecorder:
        """A recorder writing a NEW file `<directory>/<UTC timestamp>_<name>.mcap`.

        `name` defaults to the source's file or folder name; a suffix `-2`, `-3`, ... is added
        when the name is taken. Other keyword options are those of `SessionRecorder(...)`.
        """
        directory = Path(directory)
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise SessionError(f"cannot create sessions folder {directory}: {error}") from error
        stem = f"{datetime.now(UTC):%Y%m%d-%H%M%S}_{_safe_name(name or Path(source).name)}"
        for attempt in range(1, 1000):
            candidate = directory / (f"{stem}.mcap" if attempt == 1 else f"{stem}-{attempt}.mcap")
            if candidate.exists():
                continue
            try:
                return cls(candidate, source=source, tracker_params=tracker_params, **options)
            except _SessionFileExistsError:  # created by someone else in between
                continue
        raise SessionError(f"no free session file name for {stem} in {directory}")

    # -- public logging API --------------------------------------------------------------------

    @property
    def saved_frame_index(self) -> int | None:
        """Highest frame index with records that reached the OS (survive a crash), or None.

        Records reach the file in the order they were logged, so everything logged before them
        (all earlier frames, when frames are logged in order) is saved too.
        """
        with self._lock:
            return self._saved_frame_index

    def log_target(
        self, target_id: str, result: TrackResult, *, landmark_id: str | None = None
    ) -> None:
        """Record one target in one frame: box, signals and (if record_maps) the two maps."""
        target_id = _check_target_id(target_id)
        time_ns = frame_time_ns(result.frame_index, self.fps)
        box = _box_list(result.box)
        response_range = local_range = None
        maps: list[tuple[str, dict[str, Any]]] = []
        if self.record_maps:
            for kind, values in (
                ("response", result.response_map),
                ("local_variation", result.local_variation),
            ):
                if values is None:
                    continue
                quantised, lo, hi = quantise_map(values)
                frame_id = f"{target_id}/{kind}"
                maps.append((kind, foxglove.raw_image_mono8(time_ns, frame_id, quantised)))
                if kind == "response":
                    response_range = [_finite_or_none(lo), _finite_or_none(hi)]
                else:
                    local_range = [_finite_or_none(lo), _finite_or_none(hi)]
        signals = {
            "timestamp": foxglove.timestamp(time_ns),
            "frame_index": int(result.frame_index),
            "target_id": target_id,
            "box": [_finite_or_none(v) for v in box],
            "peak_score": _finite_or_none(result.peak_score),
            "aberrant": bool(result.aberrant),
            "theta_ref": _finite_or_none(result.theta_ref),
            "theta": _finite_or_none(result.theta),
            "global_variation": _finite_or_none(result.global_variation),
            "scale_factor": _finite_or_none(result.scale_factor),
            "search_box": _jsonable(list(result.search_box))
            if result.search_box is not None
            else None,
            "landmark_id": None if landmark_id is None else str(landmark_id),
            "response_range": response_range,
            "local_variation_range": local_range,
        }
        messages: list[tuple[str, str, dict[str, Any]]] = [
            (f"/targets/{target_id}/signals", "autotrack.TargetSignals", signals)
        ]
        if all(math.isfinite(v) for v in box):
            with self._lock:
                rgba = self._target_colours.setdefault(
                    target_id, _PALETTE[len(self._target_colours) % len(_PALETTE)]
                )
            score = result.peak_score
            label = target_id if not math.isfinite(score) else f"{target_id} {score:.2f}"
            if result.aberrant:
                label += " aberrant"
                rgba = _ABERRANT_RGBA
            annotations = foxglove.box_annotations(time_ns, box, label, rgba)
            messages.append(
                (f"/targets/{target_id}/box", foxglove.IMAGE_ANNOTATIONS.full_name, annotations)
            )
        for kind, image in maps:
            messages.append((f"/targets/{target_id}/{kind}", foxglove.RAW_IMAGE.full_name, image))
        self._write(messages, time_ns, int(result.frame_index))

    def log_event(
        self,
        kind: str,
        frame_index: int,
        target_id: str | None = None,
        box: Sequence[float] | None = None,
        **extra: Any,
    ) -> None:
        """Record a user edit or session event and flush it at once.

        kind: "box_drawn", "box_corrected", "box_deleted", or another lower_snake_case kind.
        extra: further JSON-serialisable details (e.g. previous_box=..., reason=...).
        """
        if not _EVENT_KIND.match(str(kind)):
            raise SessionError(f"event kind {kind!r} must be lower_snake_case, e.g. 'box_drawn'")
        if target_id is not None:
            target_id = _check_target_id(target_id)
        time_ns = frame_time_ns(frame_index, self.fps)
        payload = {
            "timestamp": foxglove.timestamp(time_ns),
            "kind": str(kind),
            "frame_index": int(frame_index),
            "target_id": target_id,
            "box": None if box is None else _jsonable(_box_list(box)),
            "wall_time": time.time(),
            "extra": _jsonable(extra),
        }
        self._write(
            [(TOPIC_EVENTS, "autotrack.SessionEvent", payload)],
            time_ns,
            int(frame_index),
            flush_now=True,
        )

    def log_pose(self, pose: PoseLike) -> None:
        """Record the camera pose of one frame: quality always; PoseInFrame and /tf when valid.

        `pose` is an autotrack.localize.PoseEstimate or any object with its attributes:
        frame_index, valid, rotation (camera-to-world), position, reprojection_errors,
        used_landmarks, reason and quaternion_xyzw().
        """
        frame_index = int(pose.frame_index)
        time_ns = frame_time_ns(frame_index, self.fps)
        errors = {
            str(key): _finite_or_none(value)
            for key, value in dict(getattr(pose, "reprojection_errors", None) or {}).items()
        }
        finite_errors = [value for value in errors.values() if value is not None]
        used = getattr(pose, "used_landmarks", None)
        quality = {
            "timestamp": foxglove.timestamp(time_ns),
            "frame_index": frame_index,
            "valid": bool(pose.valid),
            "reason": str(getattr(pose, "reason", None) or ""),
            "reprojection_errors": errors,
            "mean_reprojection_error": float(np.mean(finite_errors)) if finite_errors else None,
            "used_landmarks": None if used is None else [str(v) for v in used],
            "rms_error_px": _finite_or_none(getattr(pose, "rms_error_px", None)),
            "position_std_m": _finite_or_none(getattr(pose, "position_std_m", None)),
        }
        messages: list[tuple[str, str, dict[str, Any]]] = [
            (TOPIC_POSE_QUALITY, "autotrack.PoseQuality", quality)
        ]
        if pose.valid:
            position = np.asarray(pose.position, dtype=np.float64).reshape(3)
            quaternion = np.asarray(pose.quaternion_xyzw(), dtype=np.float64).reshape(4)
            if not (np.isfinite(position).all() and np.isfinite(quaternion).all()):
                raise SessionError(f"frame {frame_index}: a valid pose needs finite values")
            messages.append(
                (
                    TOPIC_POSE,
                    foxglove.POSE_IN_FRAME.full_name,
                    foxglove.pose_in_frame(time_ns, WORLD_FRAME, position, quaternion),
                )
            )
            messages.append(
                (
                    TOPIC_TF,
                    foxglove.FRAME_TRANSFORM.full_name,
                    foxglove.frame_transform(
                        time_ns, WORLD_FRAME, CAMERA_FRAME, position, quaternion
                    ),
                )
            )
        self._write(messages, time_ns, frame_index)

    def log_frame(self, frame_index: int, image_rgb: np.ndarray) -> bool:
        """Record a video frame as JPEG (foxglove.CompressedImage) if embed_frames is on.

        Returns True when the frame was recorded, False when embedding is off.
        """
        if not self.embed_frames:
            return False
        import cv2

        image = np.asarray(image_rgb)
        if image.dtype != np.uint8 or image.ndim not in (2, 3):
            raise SessionError("log_frame needs a uint8 HxW or HxWx3 RGB image")
        bgr = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        ok, encoded = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
        if not ok:
            raise SessionError(f"frame {frame_index}: JPEG encoding failed")
        time_ns = frame_time_ns(frame_index, self.fps)
        message = foxglove.compressed_image(time_ns, CAMERA_FRAME, encoded.tobytes(), "jpeg")
        self._write(
            [(TOPIC_IMAGE, foxglove.COMPRESSED_IMAGE.full_name, message)],
            time_ns,
            int(frame_index),
        )
        return True

    def log_landmarks(
        self, scene: Any, *, frame_index: int = 0, marker_size: float | None = None
    ) -> None:
        """Record the scene's landmarks (foxglove.SceneUpdate in the world frame).

        `scene` is an autotrack.scene.Scene (its `landmarks`), a mapping id -> (x, y, z), or an
        iterable of objects with `id` and `position`. Spheres are `marker_size` across (default
        2% of the landmarks' extent).
        """
        landmarks = _landmark_positions(scene)
        if marker_size is None:
            points = np.array([p for _, p in landmarks]) if landmarks else np.zeros((1, 3))
            extent = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
            marker_size = 0.02 * extent if extent > 0 else 0.1
        time_ns = frame_time_ns(frame_index, self.fps)
        update = foxglove.landmark_scene_update(time_ns, WORLD_FRAME, landmarks, marker_size)
        self._write(
            [(TOPIC_LANDMARKS, foxglove.SCENE_UPDATE.full_name, update)],
            time_ns,
            None,
            flush_now=True,
        )

    def flush(self) -> None:
        """Hand everything recorded so far to the OS now."""
        with self._lock:
            self._raise_if_unusable()
            self._flush_locked()

    def close(self) -> None:
        """Write the summary and footer and close the file. Safe to call twice."""
        if self._closed:
            return
        self._stop.set()
        self._flusher.join()
        with self._lock:
            self._closed = True
            try:
                self._writer.finish()
                self._file.flush()
                if self._fsync:
                    os.fsync(self._file.fileno())
            except OSError as error:
                raise SessionError(f"cannot finish session file {self.path}: {error}") from error
            finally:
                self._file.close()

    def __enter__(self) -> SessionRecorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    # -- internals -----------------------------------------------------------------------------

    def _raise_if_unusable(self) -> None:
        if self._closed:
            raise SessionError(f"session {self.path.name} is closed")
        if self._flush_error is not None:
            raise SessionError(
                f"writing session {self.path} failed: {self._flush_error}"
            ) from self._flush_error

    def _channel_id(self, topic: str, schema_name: str) -> int:
        channel_id = self._channel_ids.get(topic)
        if channel_id is None:
            schema_id = self._schema_ids.get(schema_name)
            if schema_id is None:
                schema_id = self._writer.register_schema(
                    schema_name, "jsonschema", SCHEMAS[schema_name]
                )
                self._schema_ids[schema_name] = schema_id
            channel_id = self._writer.register_channel(topic, "json", schema_id)
            self._channel_ids[topic] = channel_id
        return channel_id

    def _write(
        self,
        messages: list[tuple[str, str, dict[str, Any]]],
        time_ns: int,
        frame_index: int | None,
        *,
        flush_now: bool = False,
    ) -> None:
        encoded = [(topic, schema, _encode(payload)) for topic, schema, payload in messages]
        with self._lock:
            self._raise_if_unusable()
            publish_ns = time.time_ns()
            try:
                for topic, schema, data in encoded:
                    self._sequence += 1
                    self._writer.add_message(
                        self._channel_id(topic, schema),
                        time_ns,
                        data,
                        publish_ns,
                        sequence=self._sequence,
                    )
                now = time.monotonic()
                if self._pending_since is None:
                    self._pending_since = now
                if frame_index is not None:
                    self._pending_max_frame = max(self._pending_max_frame or 0, frame_index)
                if flush_now or now - self._pending_since >= self.flush_interval:
                    self._flush_locked()
            except OSError as error:
                self._flush_error = error
                raise SessionError(f"writing session {self.path} failed: {error}") from error

    def _flush_locked(self) -> None:
        self._writer.flush()
        if self._fsync:
            os.fsync(self._file.fileno())
        if self._pending_max_frame is not None:
            self._saved_frame_index = max(self._saved_frame_index or 0, self._pending_max_frame)
        self._pending_since = None
        self._pending_max_frame = None

    def _flush_loop(self) -> None:
        timeout = self.flush_interval
        while not self._stop.wait(timeout):
            with self._lock:
                if self._closed or self._flush_error is not None:
                    return
                timeout = self.flush_interval
                if self._pending_since is None:
                    continue
                due = self._pending_since + self.flush_interval - time.monotonic()
                if due > 0:
                    timeout = due
                    continue
                try:
                    self._flush_locked()
                except OSError as error:
                    self._flush_error = error
                    return


# --- reading ----------------------------------------------------------------------------------


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
    scene_attachment: bytes | None = field(default=None, repr=False)
    """Contents of the scene file recorded with the session, if any."""

    @property
    def frame_count(self) -> int:
        """Number of frames with at least one target result."""
        if not self.tracks:
            return 0
        has_box = np.zeros(len(self.frame_indices), dtype=bool)
        for boxes in self.tracks.values():
            has_box |= np.isfinite(boxes).all(axis=1)
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


def last_state(session: Session) -> dict[str, tuple[int, tuple[float, float, float, float]]]:
    """Where to resume: target id -> (frame index, box) of its latest record or box edit.

    Targets deleted by a `box_deleted` event (and not recreated) are left out.
    """
    return dict(session.last_boxes)


class _PrefixReader(io.RawIOBase):
    """Read-only view of the first `limit` bytes of a binary file."""

    def __init__(self, handle: BinaryIO, limit: int) -> None:
        self._handle = handle
        self._remaining = limit

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        view = memoryview(buffer)
        wanted = min(len(view), self._remaining)
        if wanted <= 0:
            return 0
        data = self._handle.read(wanted)
        view[: len(data)] = data
        self._remaining -= len(data)
        return len(data)


def _scan_records(handle: BinaryIO, size: int, name: str) -> tuple[int, bool]:
    """Walk the top-level records: (end of the last complete data-section record, file complete).

    A record whose length runs past the end of the file is where the file was cut.
    """
    handle.seek(0)
    if handle.read(len(_MCAP_MAGIC)) != _MCAP_MAGIC:
        raise SessionError(f"{name} is not an MCAP file (it does not start with the MCAP magic)")
    offset = len(_MCAP_MAGIC)
    data_end = offset
    in_data_section = True
    while size - offset >= 9:
        handle.seek(offset)
        opcode, length = struct.unpack("<BQ", handle.read(9))
        if opcode not in _KNOWN_OPCODES and opcode < 0x80:
            raise SessionError(
                f"{name} is corrupted: unknown record type 0x{opcode:02x} at byte {offset}"
            )
        end = offset + 9 + length
        if end > size:
            break
        if opcode == _OPCODE_FOOTER:
            handle.seek(end)
            return data_end, handle.read(len(_MCAP_MAGIC)) == _MCAP_MAGIC
        if in_data_section:
            data_end = end
        if opcode == _OPCODE_DATA_END:
            in_data_section = False
        offset = end
    return data_end, False


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
        target_match = _TARGET_TOPIC.match(topic)
        if target_match:
            target_id, kind = target_match.groups()
            if kind == "signals":
                self._add_signals(target_id, json.loads(message.data))
            elif kind != "box" and self.load_maps:
                image = json.loads(message.data)
                pixels = np.frombuffer(base64.b64decode(image["data"]), dtype=np.uint8)
                pixels = pixels.reshape(int(image["height"]), int(image["step"]))
                self.maps[kind].setdefault(target_id, {})[message.log_time] = pixels[
                    :, : int(image["width"])
                ]
        elif topic == TOPIC_POSE_QUALITY:
            self.pose_quality[message.log_time] = json.loads(message.data)
        elif topic == TOPIC_POSE:
            self.pose_values[message.log_time] = json.loads(message.data)["pose"]
        elif topic == TOPIC_EVENTS:
            self._add_event(json.loads(message.data))
        elif topic == TOPIC_LANDMARKS:
            update = json.loads(message.data)
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
        elif topic == TOPIC_IMAGE:
            self.image_count += 1

    def _add_signals(self, target_id: str, row: dict[str, Any]) -> None:
        if target_id not in self.target_rows:
            self.target_rows[target_id] = {}
            self.target_order.append(target_id)
        frame_index = int(row["frame_index"])
        self.target_rows[target_id][frame_index] = row  # a re-tracked frame: the later one wins
        box = _box_tuple(row["box"])
        if all(math.isfinite(v) for v in box):
            self.last_boxes[target_id] = (frame_index, box)

    def _add_event(self, payload: dict[str, Any]) -> None:
        box = payload.get("box")
        event = SessionEvent(
            kind=str(payload["kind"]),
            frame_index=int(payload["frame_index"]),
            target_id=payload.get("target_id"),
            box=None if box is None else _box_tuple(box),
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

    def build(self, path: Path, truncated: bool, bytes_read: int, file_size: int) -> Session:
        assert self.metadata is not None
        metadata: dict[str, Any] = dict(self.metadata)
        fps = float(metadata.get("fps", DEFAULT_FPS))
        metadata["fps"] = fps
        metadata["tracker_params"] = json.loads(metadata.get("tracker_params") or "{}")
        last_frames = [max(rows) for rows in self.target_rows.values() if rows]
        last_frames += [int(q["frame_index"]) for q in self.pose_quality.values()]
        count = max(last_frames) + 1 if last_frames else 0
        frame_indices = np.arange(count, dtype=np.int64)
        tracks: dict[str, np.ndarray] = {}
        scores: dict[str, np.ndarray] = {}
        aberrant: dict[str, np.ndarray] = {}
        signals: dict[str, dict[str, np.ndarray]] = {}
        landmark_ids: dict[str, str | None] = {}
        frame_of_time: dict[str, dict[int, tuple[int, list[Any] | None, list[Any] | None]]] = {}
        for target_id in self.target_order:
            rows = self.target_rows[target_id]
            boxes = np.full((count, 4), np.nan)
            score = np.full(count, np.nan)
            flags = np.zeros(count, dtype=bool)
            values = {name: np.full(count, np.nan) for name in _SIGNAL_NAMES}
            times: dict[int, tuple[int, list[Any] | None, list[Any] | None]] = {}
            for frame_index, row in rows.items():
                boxes[frame_index] = [_none_to_nan(v) for v in row["box"]]
                score[frame_index] = _none_to_nan(row.get("peak_score"))
                flags[frame_index] = bool(row.get("aberrant"))
                for name in _SIGNAL_NAMES:
                    values[name][frame_index] = _none_to_nan(row.get(name))
                stamp = row["timestamp"]
                time_ns = int(stamp["sec"]) * 1_000_000_000 + int(stamp["nsec"])
                times[time_ns] = (
                    frame_index,
                    row.get("response_range"),
                    row.get("local_variation_range"),
                )
                landmark_ids[target_id] = row.get("landmark_id")
            tracks[target_id], scores[target_id], aberrant[target_id] = boxes, score, flags
            signals[target_id] = values
            frame_of_time[target_id] = times
        response_maps, local_maps = self._dequantised_maps(frame_of_time)
        return Session(
            path=path,
            format_version=int(metadata.get("format_version", FORMAT_VERSION)),
            metadata=metadata,
            truncated=truncated,
            fps=fps,
            targets=tuple(self.target_order),
            frame_indices=frame_indices,
            tracks=tracks,
            scores=scores,
            aberrant=aberrant,
            signals=signals,
            landmark_ids=landmark_ids,
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
        )

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
                    lo, hi = (_none_to_nan(v) for v in times[time_ns][range_index])
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
                {k: _none_to_nan(v) for k, v in (q.get("reprojection_errors") or {}).items()}
                for _, q in ordered
            ),
            mean_reprojection_error=np.array(
                [_none_to_nan(q.get("mean_reprojection_error")) for _, q in ordered],
                dtype=np.float64,
            ),
            rms_error_px=np.array(
                [_none_to_nan(q.get("rms_error_px")) for _, q in ordered], dtype=np.float64
            ),
            position_std_m=np.array(
                [_none_to_nan(q.get("position_std_m")) for _, q in ordered], dtype=np.float64
            ),
            used_landmarks=tuple(
                tuple(str(v) for v in (q.get("used_landmarks") or ())) for _, q in ordered
            ),
            reasons=tuple(q.get("reason") or "" for _, q in ordered),
        )


def _iter_records(handle: BinaryIO, limit: int) -> Iterator[Any]:
    handle.seek(0)
    reader = StreamReader(_PrefixReader(handle, limit), validate_crcs=True)
    records = reader.records
    while True:
        try:
            record = next(records)
        except (StopIteration, EndOfFile):
            return
        yield record
        if isinstance(record, DataEnd):
            return


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
        limit, complete = _scan_records(handle, size, name)
        builder = _SessionBuilder(load_maps)
        try:
            for record in _iter_records(handle, limit):
                builder.add(record)
                if isinstance(record, Metadata) and record.name == SESSION_METADATA_NAME:
                    _check_version(builder.metadata or {}, name)
        except _NewerFormatError:
            raise
        except SessionError as error:
            raise SessionError(f"{name} is corrupted: {error}") from error
        except (
            McapError,
            CRCValidationError,
            zstandard.ZstdError,
            struct.error,
            UnicodeDecodeError,
            json.JSONDecodeError,
            KeyError,
            TypeError,
            ValueError,
        ) as error:
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
    return builder.build(path, truncated=not complete, bytes_read=limit, file_size=size)


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
            f"({_package_version()}) reads format versions up to {FORMAT_VERSION}: "
            "upgrade autotrack-studio to open it"
        )


class _SessionFileExistsError(SessionError):
    """The session file to create already exists."""


class _NewerFormatError(SessionError):
    """Raised for a session written by a newer format version (never reported as corruption)."""


# --- export -----------------------------------------------------------------------------------


def write_otb_tracks(
    session: Session, directory: str | Path, *, overwrite: bool = False
) -> list[Path]:
    """One `<target>.txt` per target in the benchmark format (autotrack.datasets.write_boxes):
    a line `x,y,w,h` per frame 0..last, 1-BASED x and y, `NaN` where the target has no box.
    Targets the user deleted are not written."""
    from autotrack.evaluation.datasets import write_boxes

    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise SessionError(f"cannot create {directory}: {error}") from error
    targets = session.exported_targets
    paths = [directory / f"{target_id}.txt" for target_id in targets]
    taken = [str(path) for path in paths if path.exists()]
    if taken and not overwrite:
        raise SessionError(
            f"{', '.join(taken)} already exist(s); not replaced (--force / overwrite=True "
            "replaces them)"
        )
    for target_id, path in zip(targets, paths, strict=True):
        try:
            write_boxes(path, session.tracks[target_id])
        except OSError as error:
            raise SessionError(f"cannot write {path}: {error}") from error
    return paths


def write_tracks_csv(session: Session, path: str | Path, *, overwrite: bool = False) -> Path:
    """Combined CSV: frame (0-based), target, x, y, w, h (0-based pixels), score, aberrant (0/1);
    one row per frame and target with a box, ordered by frame then target."""
    lines = ["frame,target,x,y,w,h,score,aberrant"]
    targets = session.exported_targets
    for frame_index in session.frame_indices:
        for target_id in targets:
            box = session.tracks[target_id][frame_index]
            if not np.isfinite(box).all():
                continue
            score = session.scores[target_id][frame_index]
            flag = int(session.aberrant[target_id][frame_index])
            coordinates = ",".join(repr(float(v)) for v in box)
            lines.append(f"{frame_index},{target_id},{coordinates},{float(score)!r},{flag}")
    path = Path(path)
    _write_text(path, "\n".join(lines) + "\n", overwrite)
    return path


def write_tum_poses(session: Session, path: str | Path, *, overwrite: bool = False) -> int:
    """The session's valid camera poses as a TUM file (for evo); timestamp = frame index / fps.

    Returns the number of poses written.
    """
    from autotrack.localization.localizer import write_tum

    path = Path(path)
    if path.exists() and not overwrite:
        raise SessionError(
            f"{path} already exists; not replaced (--force / overwrite=True replaces it)"
        )
    poses = session.poses
    keep = poses.valid
    try:
        return write_tum(
            path,
            poses.frame_indices[keep] / session.fps,
            poses.positions[keep],
            poses.quaternions_xyzw[keep],
        )
    except OSError as error:
        raise SessionError(f"cannot write {path}: {error}") from error


def _write_text(path: Path, text: str, overwrite: bool) -> None:
    try:
        with open(path, "w" if overwrite else "x", encoding="utf-8") as handle:
            handle.write(text)
    except FileExistsError as error:
        raise SessionError(
            f"{path} already exists; not replaced (--force / overwrite=True replaces it)"
        ) from error
    except OSError as error:
        raise SessionError(f"cannot write {path}: {error}") from error
