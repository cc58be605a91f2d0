"""The session's channels: their JSON schemas, encodings and topics.

Every schema is a JSON file in `jsonschema/` (Foxglove's published well-known schemas, and
ours), loaded here with importlib.resources; schema and message encodings are the constants of
`mcap.well_known`. Topics are built and read back by `TargetTopic` and the `Topics` constants,
nowhere else.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from enum import StrEnum
from functools import cache
from importlib import resources
from typing import Any

from mcap.well_known import MessageEncoding, SchemaEncoding

from autotrack.errors import SessionError

SCHEMA_ENCODING = SchemaEncoding.JSONSchema
"""Encoding of every schema we register ("jsonschema")."""
MESSAGE_ENCODING = MessageEncoding.JSON
"""Encoding of every message we write ("json")."""

FOXGLOVE_IMAGE_ANNOTATIONS = "foxglove.ImageAnnotations"
FOXGLOVE_RAW_IMAGE = "foxglove.RawImage"
FOXGLOVE_COMPRESSED_IMAGE = "foxglove.CompressedImage"
FOXGLOVE_POSE_IN_FRAME = "foxglove.PoseInFrame"
FOXGLOVE_FRAME_TRANSFORM = "foxglove.FrameTransform"
FOXGLOVE_SCENE_UPDATE = "foxglove.SceneUpdate"
TARGET_SIGNALS = "autotrack.TargetSignals"
POSE_QUALITY = "autotrack.PoseQuality"
SESSION_EVENT = "autotrack.SessionEvent"

SCHEMA_NAMES = (
    FOXGLOVE_IMAGE_ANNOTATIONS,
    FOXGLOVE_RAW_IMAGE,
    FOXGLOVE_COMPRESSED_IMAGE,
    FOXGLOVE_POSE_IN_FRAME,
    FOXGLOVE_FRAME_TRANSFORM,
    FOXGLOVE_SCENE_UPDATE,
    TARGET_SIGNALS,
    POSE_QUALITY,
    SESSION_EVENT,
)
"""Every schema a session uses, by the name its JSON file and MCAP schema record carry."""

WORLD_FRAME = "world"
CAMERA_FRAME = "camera"


@cache
def schema_document(name: str) -> dict[str, Any]:
    """The JSON Schema document named `name` (e.g. "foxglove.RawImage")."""
    if name not in SCHEMA_NAMES:
        raise SessionError(f"no schema named {name!r}")
    path = resources.files("autotrack.sessions") / "jsonschema" / f"{name}.json"
    return json.loads(path.read_text(encoding="utf-8"))


def schema_bytes(name: str) -> bytes:
    """The schema as written into a session file (compact JSON)."""
    return json.dumps(schema_document(name), separators=(",", ":")).encode("utf-8")


@dataclass(frozen=True)
class Topic:
    """A channel of fixed name and the schema of its messages."""

    name: str
    schema: str


class Topics:
    """The session's fixed channels."""

    POSE = Topic("/camera/pose", FOXGLOVE_POSE_IN_FRAME)
    TF = Topic("/tf", FOXGLOVE_FRAME_TRANSFORM)
    POSE_QUALITY = Topic("/camera/pose_quality", POSE_QUALITY)
    LANDMARKS = Topic("/landmarks", FOXGLOVE_SCENE_UPDATE)
    EVENTS = Topic("/events", SESSION_EVENT)
    IMAGE = Topic("/camera/image", FOXGLOVE_COMPRESSED_IMAGE)


class TargetStream(StrEnum):
    """What a target's channel carries."""

    BOX = "box"
    SIGNALS = "signals"
    RESPONSE = "response"
    LOCAL_VARIATION = "local_variation"
    SPATIAL_WINDOW = "spatial_window"
    """The spatial regularisation weights the filter was trained with, quantised in log10."""

    @property
    def schema(self) -> str:
        """Schema name of this stream's messages."""
        if self is TargetStream.BOX:
            return FOXGLOVE_IMAGE_ANNOTATIONS
        if self is TargetStream.SIGNALS:
            return TARGET_SIGNALS
        return FOXGLOVE_RAW_IMAGE


_TARGETS_PREFIX = "/targets/"


@dataclass(frozen=True)
class TargetTopic:
    """`/targets/<target id>/<stream>`: one stream of one target."""

    target_id: str
    stream: TargetStream

    @property
    def topic(self) -> Topic:
        """The channel (name and schema)."""
        return Topic(f"{_TARGETS_PREFIX}{self.target_id}/{self.stream.value}", self.stream.schema)

    @classmethod
    def parse(cls, name: str) -> TargetTopic | None:
        """The target stream a channel name denotes, or None for another channel."""
        if not name.startswith(_TARGETS_PREFIX):
            return None
        target_id, _, stream = name[len(_TARGETS_PREFIX) :].partition("/")
        if not target_id or stream not in TargetStream.__members__.values():
            return None
        return cls(target_id, TargetStream(stream))
