"""Recording a session: every tracked frame, pose and user edit, to one MCAP file.

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

import math
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import Any, BinaryIO

import numpy as np
from mcap.writer import CompressionType, Writer

import autotrack
from autotrack.errors import SessionError
from autotrack.params import TrackerParams
from autotrack.result import PoseEstimate, TrackResult
from autotrack.sessions import messages
from autotrack.sessions.encoding import (
    DEFAULT_FPS,
    SESSION_METADATA_NAME,
    encode_json,
    frame_time_ns,
)
from autotrack.sessions.metadata import path_text, session_metadata
from autotrack.sessions.names import (
    check_event_kind,
    check_landmark_id,
    check_target_id,
    safe_file_name,
)
from autotrack.sessions.output import SessionFile
from autotrack.sessions.schemas import (
    CAMERA_FRAME,
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    WORLD_FRAME,
    Topic,
    Topics,
    schema_bytes,
)

EMBEDDED_IMAGE_FORMATS = ("jpeg", "png")
"""The encodings of embedded frames (foxglove.CompressedImage formats every viewer decodes)."""
DEFAULT_FLUSH_INTERVAL_S = 1.0
"""Longest time a recorded message waits in memory before it reaches the OS (seconds)."""
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
        tracker: str | None = None,
        scene_path: str | Path | None = None,
        fps: float | None = None,
        embed_frames: bool = False,
        record_maps: bool = True,
        jpeg_quality: int = 90,
        flush_interval: float = DEFAULT_FLUSH_INTERVAL_S,
        fsync: bool = False,
        resumed_from: str | Path | None = None,
        live_source: bool = False,
    ) -> None:
        """Create the session file at exactly `path`; an existing file is never overwritten.

        source: what was tracked (sequence folder, video file, camera name).
        tracker_params: the parameters of the tracker(s) of this session.
        tracker: its name (`nanotrack`, `hybrid`; None: the preset `tracker_params` describe).
        scene_path: localisation scene file; recorded by name and embedded as an attachment.
        fps: frame rate of the source; log times are frame_index / fps (DEFAULT_FPS if None).
        embed_frames: record the video frames (`log_frame`, `log_encoded_frame`) on the camera
            topic; off unless asked for here (a pipeline's `Recording` asks by default).
        record_maps: record the response and local-variation maps and the spatial weights
            (log10), mono8, ~2.5 kB each.
        jpeg_quality: JPEG quality of embedded frames (0-100).
        flush_interval: longest time (s) a message waits in memory before reaching the OS.
        fsync: also fsync the file at each flush (survives power loss, slower).
        resumed_from: the session this one continues, if any.
        live_source: the frames come from a live source (a camera, a stream): a reopened
            session is looked through on its embedded frames (`Session.recorded_live`).
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
        scene_bytes = None if scene_path is None else _read_scene(scene_path)
        # Everything is checked and built before the file exists: a refusal leaves no file.
        self.metadata = session_metadata(
            source=source,
            fps=self.fps,
            fps_given=fps is not None,
            tracker_params=tracker_params,
            tracker=tracker,
            scene_path=scene_path,
            embed_frames=self.embed_frames,
            record_maps=self.record_maps,
            flush_interval=self.flush_interval,
            resumed_from=resumed_from,
            live_source=live_source,
        )
        self._file = SessionFile(_create_file(self.path), self.path, fsync=self._fsync)
        self._lock = threading.Lock()
        self._writer = Writer(
            self._file, compression=CompressionType.ZSTD, enable_crcs=True, enable_data_crcs=True
        )
        self._schema_ids: dict[str, int] = {}
        self._channel_ids: dict[str, int] = {}
        self._target_colours: dict[str, tuple[float, float, float, float]] = {}
        self._sequence = 0
        self._pending_since: float | None = None
        self._closed = False
        self._start(None if scene_path is None else path_text(Path(scene_path).name), scene_bytes)
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
        stem = f"{datetime.now(UTC):%Y%m%d-%H%M%S}_{safe_file_name(name or Path(source).name)}"
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

    def log_target(
        self, target_id: str, result: TrackResult, *, landmark_id: str | None = None
    ) -> None:
        """Record one target in one frame: box, signals and (if record_maps) its maps."""
        target_id = check_target_id(target_id)
        check_landmark_id(landmark_id)
        rgba = _ABERRANT_RGBA
        if all(math.isfinite(v) for v in result.box):
            with self._lock:
                rgba = self._target_colours.setdefault(
                    target_id, _PALETTE[len(self._target_colours) % len(_PALETTE)]
                )
        time_ns = frame_time_ns(result.frame_index, self.fps)
        batch = messages.target_messages(
            time_ns,
            target_id,
            result,
            landmark_id=landmark_id,
            record_maps=self.record_maps,
            rgba=_ABERRANT_RGBA if result.aberrant else rgba,
        )
        self._write(batch, time_ns)

    def log_no_result(
        self, target_id: str, frame_index: int, *, landmark_id: str | None = None
    ) -> None:
        """Record that a target has no result on `frame_index` any more (it was re-tracked from
        an earlier frame): the reader keeps the latest record per frame, and this one has no
        box."""
        nan = math.nan
        cleared = TrackResult(
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
        self.log_target(target_id, cleared, landmark_id=landmark_id)

    def log_no_pose(self, frame_index: int, reason: str) -> None:
        """Record that the pose of `frame_index` no longer holds (`reason` says why)."""
        self.log_pose(
            PoseEstimate(
                frame_index=frame_index,
                valid=False,
                rotation=np.full((3, 3), np.nan),
                position=np.full(3, np.nan),
                reprojection_errors={},
                used_landmarks=(),
                reason=reason,
            )
        )

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
        check_event_kind(kind)
        if target_id is not None:
            target_id = check_target_id(target_id)
        check_landmark_id(extra.get("landmark_id"))
        time_ns = frame_time_ns(frame_index, self.fps)
        message = messages.event_message(
            time_ns, str(kind), int(frame_index), target_id, box, extra, wall_time=time.time()
        )
        self._write([message], time_ns, flush_now=True)

    def log_pose(self, pose: messages.PoseLike) -> None:
        """Record the camera pose of one frame: quality always; PoseInFrame and /tf when valid.

        `pose` is an autotrack.result.PoseEstimate or any object with its attributes:
        frame_index, valid, rotation (camera-to-world), position, reprojection_errors,
        used_landmarks, reason and quaternion_xyzw().
        """
        frame_index = int(pose.frame_index)
        time_ns = frame_time_ns(frame_index, self.fps)
        self._write(messages.pose_messages(time_ns, pose), time_ns)

    def log_frame(self, frame_index: int, image_rgb: np.ndarray) -> bool:
        """Record a decoded video frame, encoded once as JPEG (`jpeg_quality`), on the camera
        topic (foxglove.CompressedImage, frame `camera`) if embed_frames is on.

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
        return self.log_encoded_frame(frame_index, encoded.tobytes(), "jpeg")

    def log_encoded_frame(self, frame_index: int, data: bytes, image_format: str) -> bool:
        """Record a video frame already encoded (a JPEG or PNG file's bytes, as they are) on the
        camera topic if embed_frames is on; returns whether it was recorded."""
        if image_format not in EMBEDDED_IMAGE_FORMATS:
            raise SessionError(
                f"frame {frame_index}: embedded frames are {' or '.join(EMBEDDED_IMAGE_FORMATS)}, "
                f"not {image_format!r}"
            )
        if not self.embed_frames:
            return False
        time_ns = frame_time_ns(frame_index, self.fps)
        message = messages.compressed_image(time_ns, CAMERA_FRAME, bytes(data), image_format)
        self._write([(Topics.IMAGE, message)], time_ns)
        return True

    def log_landmarks(
        self, scene: Any, *, frame_index: int = 0, marker_size: float | None = None
    ) -> None:
        """Record the scene's landmarks (foxglove.SceneUpdate in the world frame).

        `scene` is an autotrack.localization.scene.Scene (its `landmarks`), a mapping
        id -> (x, y, z), or an iterable of objects with `id` and `position`. Spheres are
        `marker_size` across (default 2% of the landmarks' extent).
        """
        landmarks = messages.landmark_positions(scene)
        if marker_size is None:
            points = np.array([p for _, p in landmarks]) if landmarks else np.zeros((1, 3))
            extent = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
            marker_size = 0.02 * extent if extent > 0 else 0.1
        time_ns = frame_time_ns(frame_index, self.fps)
        update = messages.landmark_scene_update(time_ns, WORLD_FRAME, landmarks, marker_size)
        self._write([(Topics.LANDMARKS, update)], time_ns, flush_now=True)

    @property
    def write_error(self) -> OSError | None:
        """The write that failed (a full disk, ...), None while every write succeeded. After it
        nothing more is written to the file, which keeps every record flushed before it and
        reads as a session cut short; every later call raises SessionWriteError."""
        return self._file.error

    def flush(self) -> None:
        """Hand everything recorded so far to the OS now."""
        with self._lock:
            self._raise_if_unusable()
            self._guarded(self._flush_locked)

    def close(self) -> None:
        """Write the summary and footer and close the file. Safe to call twice, and after a
        failed write (the file then stays as it was cut, and close does not raise again)."""
        if self._closed:
            return
        self._stop.set()
        self._flusher.join()
        with self._lock:
            self._closed = True
            if self._file.error is not None:
                return
            try:
                self._writer.finish()
                self._file.flush()
            except OSError as error:
                raise self._failed(error) from error
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

    def _start(self, scene_name: str | None, scene_bytes: bytes | None) -> None:
        """Header, metadata record and the scene attachment, handed to the OS at once."""
        try:
            self._writer.start(profile="", library=f"autotrack-studio {autotrack.__version__}")
            self._writer.add_metadata(SESSION_METADATA_NAME, self.metadata)
            if scene_bytes is not None:
                now = time.time_ns()
                self._writer.add_attachment(
                    now, 0, scene_name, "application/octet-stream", scene_bytes
                )
            self._writer.flush()
        except BaseException as error:
            self._file.close()
            self.path.unlink(missing_ok=True)  # a header cut short holds nothing: no orphan
            if isinstance(error, OSError):
                raise SessionError(f"cannot write session file {self.path}: {error}") from error
            raise

    def _raise_if_unusable(self) -> None:
        if self._file.error is not None:
            raise self._failed(self._file.error) from self._file.error
        if self._closed:
            raise SessionError(f"session {self.path.name} is closed")

    def _failed(self, error: OSError) -> SessionWriteError:
        return SessionWriteError(
            f"writing session {self.path} failed ({error.strerror or error}): recording "
            f"stopped; the file keeps everything recorded before "
            f"({self._file.flushed_bytes} bytes, readable as a session cut short)"
        )

    def _guarded(self, write: Callable[[], None]) -> None:
        """Run a write of the file; a failure becomes SessionWriteError (the file is then cut
        back to its last complete flush and written no more, `SessionFile`)."""
        try:
            write()
        except OSError as error:
            raise self._failed(error) from error

    def _channel_id(self, topic: Topic) -> int:
        channel_id = self._channel_ids.get(topic.name)
        if channel_id is None:
            schema_id = self._schema_ids.get(topic.schema)
            if schema_id is None:
                schema_id = self._writer.register_schema(
                    topic.schema, SCHEMA_ENCODING, schema_bytes(topic.schema)
                )
                self._schema_ids[topic.schema] = schema_id
            channel_id = self._writer.register_channel(topic.name, MESSAGE_ENCODING, schema_id)
            self._channel_ids[topic.name] = channel_id
        return channel_id

    def _write(
        self, batch: list[messages.Message], time_ns: int, *, flush_now: bool = False
    ) -> None:
        encoded = [(topic, encode_json(payload)) for topic, payload in batch]
        with self._lock:
            self._raise_if_unusable()
            publish_ns = time.time_ns()

            def add_and_maybe_flush() -> None:
                for topic, data in encoded:
                    self._sequence += 1
                    self._writer.add_message(
                        self._channel_id(topic), time_ns, data, publish_ns, sequence=self._sequence
                    )
                now = time.monotonic()
                if self._pending_since is None:
                    self._pending_since = now
                if flush_now or now - self._pending_since >= self.flush_interval:
                    self._flush_locked()

            self._guarded(add_and_maybe_flush)

    def _flush_locked(self) -> None:
        self._writer.flush()  # closes the chunk and flushes the SessionFile (fsync there)
        self._pending_since = None

    def _flush_loop(self) -> None:
        timeout = self.flush_interval
        while not self._stop.wait(timeout):
            with self._lock:
                if self._closed or self._file.error is not None:
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
                except OSError:
                    return  # the next call raises SessionWriteError (`write_error`)


class SessionWriteError(SessionError):
    """Writing the session file failed (e.g. the disk is full): the recording stopped, and the
    file keeps everything written before (`SessionRecorder.write_error`)."""


class _SessionFileExistsError(SessionError):
    """The session file to create already exists."""


def _read_scene(scene_path: str | Path) -> bytes:
    try:
        return Path(scene_path).read_bytes()
    except OSError as error:
        raise SessionError(f"cannot read scene file {scene_path}: {error}") from error


def _create_file(path: Path) -> BinaryIO:
    """A new file opened for writing; an existing file is never overwritten."""
    try:
        return open(path, "xb", buffering=0)  # noqa: SIM115 - closed by the recorder's close()
    except FileExistsError as error:
        raise _SessionFileExistsError(
            f"{path} already exists; session files are never overwritten"
        ) from error
    except OSError as error:
        raise SessionError(f"cannot create session file {path}: {error}") from error
