"""The messages a session holds, as JSON-ready dicts, each paired with its channel.

Foxglove's well-known messages (their schemas: `schemas`) and ours: a target's signals, the
pose quality, session events. Times are Foxglove `{"sec", "nsec"}`, bytes base64 strings, NaN
is null, as the JSON encoding requires.
"""

from __future__ import annotations

import base64
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from autotrack.errors import SessionError
from autotrack.hybrid.factory import trusted_of
from autotrack.io.ids import checked_identifier
from autotrack.result import TrackResult
from autotrack.sessions.encoding import (
    MAP_STREAMS,
    box_list,
    finite_or_none,
    jsonable,
    map_of,
    quantise_map,
)
from autotrack.sessions.schemas import (
    CAMERA_FRAME,
    WORLD_FRAME,
    TargetStream,
    TargetTopic,
    Topic,
    Topics,
)

Rgba = tuple[float, float, float, float]
Message = tuple[Topic, dict[str, Any]]
"""A message and the channel it goes to."""


class PoseLike(Protocol):
    """What the recorder reads from a camera pose (autotrack.result.PoseEstimate)."""

    frame_index: int
    valid: bool
    position: Any
    reprojection_errors: Mapping[str, float]
    reason: str | None

    def quaternion_xyzw(self) -> Any: ...


# --- small pure helpers -----------------------------------------------------------------------


def timestamp(nanoseconds: int) -> dict[str, int]:
    """A Foxglove time `{"sec", "nsec"}` from integer nanoseconds."""
    sec, nsec = divmod(int(nanoseconds), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def color(rgba: Rgba) -> dict[str, float]:
    """A Foxglove Color from (r, g, b, a) in [0, 1]."""
    r, g, b, a = rgba
    return {"r": float(r), "g": float(g), "b": float(b), "a": float(a)}


def box_annotations(
    time_ns: int, box: Sequence[float], label: str, outline: Rgba, *, thickness: float = 2.0
) -> dict[str, Any]:
    """ImageAnnotations drawing one (x, y, w, h) box as a closed polygon with a text label.

    Foxglove's image coordinates put (0, 0) at the top-left corner of the top-left pixel, the same
    origin as our 0-based boxes.
    """
    x, y, w, h = (float(v) for v in box)
    stamp = timestamp(time_ns)
    corners = [(x, y), (x + w, y), (x + w, y + h), (x, y + h)]
    return {
        "circles": [],
        "points": [
            {
                "timestamp": stamp,
                "type": 2,  # LINE_LOOP
                "points": [{"x": px, "y": py} for px, py in corners],
                "outline_color": color(outline),
                "outline_colors": [],
                "fill_color": color((0.0, 0.0, 0.0, 0.0)),
                "thickness": thickness,
            }
        ],
        "texts": [
            {
                "timestamp": stamp,
                "position": {"x": x, "y": max(y - 4.0, 0.0)},
                "text": label,
                "font_size": 14.0,
                "text_color": color(outline),
                "background_color": color((0.0, 0.0, 0.0, 0.6)),
            }
        ],
    }


def raw_image_mono8(time_ns: int, frame_id: str, pixels: np.ndarray) -> dict[str, Any]:
    """RawImage of a 2-D uint8 array, encoding `mono8`."""
    pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
    height, width = pixels.shape
    return {
        "timestamp": timestamp(time_ns),
        "frame_id": frame_id,
        "width": int(width),
        "height": int(height),
        "encoding": "mono8",
        "step": int(width),
        "data": base64.b64encode(pixels.tobytes()).decode("ascii"),
    }


def compressed_image(time_ns: int, frame_id: str, data: bytes, image_format: str) -> dict[str, Any]:
    """CompressedImage holding encoded bytes (`jpeg`, `png`, ...)."""
    return {
        "timestamp": timestamp(time_ns),
        "frame_id": frame_id,
        "data": base64.b64encode(data).decode("ascii"),
        "format": image_format,
    }


def _pose(position: Sequence[float], quaternion_xyzw: Sequence[float]) -> dict[str, Any]:
    px, py, pz = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quaternion_xyzw)
    return {
        "position": {"x": px, "y": py, "z": pz},
        "orientation": {"x": qx, "y": qy, "z": qz, "w": qw},
    }


def pose_in_frame(
    time_ns: int, frame_id: str, position: Sequence[float], quaternion_xyzw: Sequence[float]
) -> dict[str, Any]:
    """PoseInFrame: a pose (position, orientation as x, y, z, w) in `frame_id`."""
    return {
        "timestamp": timestamp(time_ns),
        "frame_id": frame_id,
        "pose": _pose(position, quaternion_xyzw),
    }


def frame_transform(
    time_ns: int,
    parent_frame_id: str,
    child_frame_id: str,
    translation: Sequence[float],
    rotation_xyzw: Sequence[float],
) -> dict[str, Any]:
    """FrameTransform: the child frame's pose in the parent frame."""
    pose = _pose(translation, rotation_xyzw)
    return {
        "timestamp": timestamp(time_ns),
        "parent_frame_id": parent_frame_id,
        "child_frame_id": child_frame_id,
        "translation": pose["position"],
        "rotation": pose["orientation"],
    }


def landmark_scene_update(
    time_ns: int,
    frame_id: str,
    landmarks: Iterable[tuple[str, Sequence[float]]],
    marker_size: float,
    rgba: Rgba = (1.0, 0.6, 0.0, 1.0),
) -> dict[str, Any]:
    """SceneUpdate with one entity per landmark: a sphere of diameter `marker_size` and its id."""
    stamp = timestamp(time_ns)
    identity = (0.0, 0.0, 0.0, 1.0)
    entities = []
    for landmark_id, position in landmarks:
        px, py, pz = (float(v) for v in position)
        label_position = (px, py, pz + marker_size)
        entities.append(
            {
                "timestamp": stamp,
                "frame_id": frame_id,
                "id": str(landmark_id),
                "lifetime": {"sec": 0, "nsec": 0},
                "frame_locked": False,
                "metadata": [],
                "arrows": [],
                "cubes": [],
                "spheres": [
                    {
                        "pose": _pose((px, py, pz), identity),
                        "size": {"x": marker_size, "y": marker_size, "z": marker_size},
                        "color": color(rgba),
                    }
                ],
                "cylinders": [],
                "lines": [],
                "triangles": [],
                "texts": [
                    {
                        "pose": _pose(label_position, identity),
                        "billboard": True,
                        "font_size": 14.0,
                        "scale_invariant": True,
                        "color": color((1.0, 1.0, 1.0, 1.0)),
                        "text": str(landmark_id),
                    }
                ],
                "models": [],
            }
        )
    return {"deletions": [], "entities": entities}


def target_messages(
    time_ns: int,
    target_id: str,
    result: TrackResult,
    *,
    landmark_id: str | None,
    record_maps: bool,
    rgba: Rgba,
) -> list[Message]:
    """One target in one frame: its signals, its box (when finite, outlined in `rgba`) and,
    with `record_maps`, the response and local-variation maps and the spatial weights (in
    log10) quantised to mono8."""
    box = box_list(result.box)
    ranges: dict[TargetStream, list[float | None] | None] = dict.fromkeys(MAP_STREAMS)
    maps: list[Message] = []
    if record_maps:
        for stream in MAP_STREAMS:
            values = map_of(result, stream)
            if values is None:
                continue
            quantised, lo, hi = quantise_map(values)
            image = raw_image_mono8(time_ns, f"{target_id}/{stream.value}", quantised)
            maps.append((TargetTopic(target_id, stream).topic, image))
            ranges[stream] = [finite_or_none(lo), finite_or_none(hi)]
    signals = {
        "timestamp": timestamp(time_ns),
        "frame_index": int(result.frame_index),
        "target_id": target_id,
        "box": [finite_or_none(v) for v in box],
        "peak_score": finite_or_none(result.peak_score),
        "aberrant": bool(result.aberrant),
        "theta_ref": finite_or_none(result.theta_ref),
        "theta": finite_or_none(result.theta),
        "global_variation": finite_or_none(result.global_variation),
        "scale_factor": finite_or_none(result.scale_factor),
        "search_box": jsonable(list(result.search_box)) if result.search_box is not None else None,
        "landmark_id": None if landmark_id is None else str(landmark_id),
        "response_range": ranges[TargetStream.RESPONSE],
        "local_variation_range": ranges[TargetStream.LOCAL_VARIATION],
        "spatial_window_range": ranges[TargetStream.SPATIAL_WINDOW],
        "trusted": trusted_of(result),
    }
    batch: list[Message] = [(TargetTopic(target_id, TargetStream.SIGNALS).topic, signals)]
    if all(math.isfinite(v) for v in box):
        score = result.peak_score
        label = target_id if not math.isfinite(score) else f"{target_id} {score:.2f}"
        if result.aberrant:
            label += " aberrant"
        annotations = box_annotations(time_ns, box, label, rgba)
        batch.append((TargetTopic(target_id, TargetStream.BOX).topic, annotations))
    return batch + maps


def event_message(
    time_ns: int,
    kind: str,
    frame_index: int,
    target_id: str | None,
    box: Sequence[float] | None,
    extra: Mapping[str, Any],
    *,
    wall_time: float,
) -> Message:
    """A user edit or session event (`wall_time`: Unix seconds when it happened)."""
    payload = {
        "timestamp": timestamp(time_ns),
        "kind": kind,
        "frame_index": frame_index,
        "target_id": target_id,
        "box": None if box is None else jsonable(box_list(box)),
        "wall_time": wall_time,
        "extra": jsonable(extra),
    }
    return (Topics.EVENTS, payload)


def pose_messages(time_ns: int, pose: PoseLike) -> list[Message]:
    """The pose quality of one frame, and when the pose is valid its PoseInFrame and /tf."""
    frame_index = int(pose.frame_index)
    errors = {
        str(key): finite_or_none(value)
        for key, value in dict(getattr(pose, "reprojection_errors", None) or {}).items()
    }
    finite_errors = [value for value in errors.values() if value is not None]
    used = getattr(pose, "used_landmarks", None)
    quality = {
        "timestamp": timestamp(time_ns),
        "frame_index": frame_index,
        "valid": bool(pose.valid),
        "reason": str(getattr(pose, "reason", None) or ""),
        "reprojection_errors": errors,
        "mean_reprojection_error": float(np.mean(finite_errors)) if finite_errors else None,
        "used_landmarks": None if used is None else [str(v) for v in used],
        "rms_error_px": finite_or_none(getattr(pose, "rms_error_px", None)),
        "position_std_m": finite_or_none(getattr(pose, "position_std_m", None)),
    }
    batch: list[Message] = [(Topics.POSE_QUALITY, quality)]
    if pose.valid:
        position = np.asarray(pose.position, dtype=np.float64).reshape(3)
        quaternion = np.asarray(pose.quaternion_xyzw(), dtype=np.float64).reshape(4)
        if not (np.isfinite(position).all() and np.isfinite(quaternion).all()):
            raise SessionError(f"frame {frame_index}: a valid pose needs finite values")
        batch.append((Topics.POSE, pose_in_frame(time_ns, WORLD_FRAME, position, quaternion)))
        transform = frame_transform(time_ns, WORLD_FRAME, CAMERA_FRAME, position, quaternion)
        batch.append((Topics.TF, transform))
    return batch


def landmark_positions(scene: Any) -> list[tuple[str, np.ndarray]]:
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
        result.append((checked_identifier(str(landmark_id), "landmark id", SessionError), point))
    return result
