"""One frame's maps read back from a session file, also one still being written (`SessionMaps`).

A long run keeps the maps of its recent frames only (`Pipeline(map_window=...)`); the app reads
an older frame's maps back from its recording. The file is not scanned for them: an index of
its chunks is built from the records between them (each chunk is followed by one message index
per channel, uncompressed: the log times of its messages), extended from where it stopped each
time the file has grown, and a frame's maps are decoded from the one or two chunks whose
target messages cover the frame's log time. A chunk is decompressed during indexing only when
it brings a channel the index has not met (its Channel record is in that chunk).
"""

from __future__ import annotations

import base64
import io
import json
import math
import struct
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, MessageIndex, Metadata
from mcap.stream_reader import StreamReader

from autotrack.errors import SessionError
from autotrack.sessions.encoding import (
    DEFAULT_FPS,
    MAP_STREAMS,
    RANGE_FIELDS,
    SESSION_METADATA_NAME,
    frame_time_ns,
    none_to_nan,
    recorded_map,
)
from autotrack.sessions.limits import DECODE_ERRORS, MAX_CHUNK_BYTES, chunk_records
from autotrack.sessions.schemas import TargetStream, TargetTopic

_MAGIC_BYTES = 8
_RECORD_HEADER = struct.Struct("<BQ")
_INDEXED = (Opcode.CHUNK, Opcode.MESSAGE_INDEX, Opcode.METADATA)
CHUNKS_CACHED = 4
"""Decoded chunks kept (seeking back and forth around one frame decodes each once)."""


@dataclass(frozen=True)
class FrameMaps:
    """A target's recorded maps on one frame (None: not recorded there), float32, centred."""

    response: np.ndarray | None
    local_variation: np.ndarray | None
    spatial_window: np.ndarray | None
    """The spatial weights the filter trained with (None: the frame did not train)."""


@dataclass
class _ChunkSpan:
    offset: int
    """Where the chunk record starts in the file."""
    first_ns: int
    """Earliest log time of a target message in the chunk."""
    last_ns: int
    """Latest log time of a target message in the chunk."""


class SessionMaps:
    """Reads targets' maps by frame from one session file (see the module docstring)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.fps = DEFAULT_FPS
        """The frame rate of the file's log times (from its session metadata)."""
        self._indexed_to = _MAGIC_BYTES
        self._complete = False
        self._channels: dict[int, TargetTopic | None] = {}
        self._spans: list[_ChunkSpan] = []
        self._last_chunk: int | None = None
        self._previous_chunk: int | None = None
        self._decoded: OrderedDict[int, list[tuple[TargetTopic, int, bytes]]] = OrderedDict()
        self.chunks_decoded = 0
        """Chunks decompressed so far (indexing and reading)."""

    def frame_maps(self, target_id: str, frame_index: int) -> FrameMaps:
        """The maps of `target_id` on `frame_index` as last recorded (a re-tracked frame's
        latest record wins); SessionError for a file that cannot be read."""
        try:
            with open(self.path, "rb") as handle:
                self._extend_index(handle)
                return self._read(handle, target_id, frame_index)
        except OSError as error:
            raise SessionError(f"cannot read session file {self.path}: {error}") from error
        except DECODE_ERRORS as error:
            raise SessionError(
                f"{self.path} is corrupted ({type(error).__name__}: {error})"
            ) from error

    # -- the index ----------------------------------------------------------------------------

    def _extend_index(self, handle: BinaryIO) -> None:
        """Index the records written since the last call (stops before one cut short)."""
        if self._complete:
            return
        size = handle.seek(0, io.SEEK_END)
        offset = self._indexed_to
        while size - offset >= _RECORD_HEADER.size:
            handle.seek(offset)
            opcode, length = _RECORD_HEADER.unpack(handle.read(_RECORD_HEADER.size))
            end = offset + _RECORD_HEADER.size + length
            if end > size:
                break  # still being written
            if opcode in (Opcode.DATA_END, Opcode.FOOTER):
                self._complete = True
                break
            if opcode == Opcode.CHUNK:
                self._previous_chunk, self._last_chunk = self._last_chunk, offset
            elif opcode in _INDEXED:
                handle.seek(offset)
                self._index_record(handle, _parsed(handle.read(end - offset)))
            offset = end
        self._indexed_to = offset

    def _index_record(self, handle: BinaryIO, record: Any) -> None:
        if isinstance(record, Metadata) and record.name == SESSION_METADATA_NAME:
            fps = float(record.metadata.get("fps", DEFAULT_FPS))
            if not (math.isfinite(fps) and fps > 0):
                raise SessionError(f"{self.path}: its frame rate {fps!r} is not positive")
            self.fps = fps
        elif isinstance(record, MessageIndex) and self._last_chunk is not None and record.records:
            if record.channel_id not in self._channels:
                self._learn_channels(handle, record.channel_id)
            if self._channels.get(record.channel_id) is None:
                return
            times = [time_ns for time_ns, _ in record.records]
            span = self._spans[-1] if self._spans else None
            if span is None or span.offset != self._last_chunk:
                span = _ChunkSpan(self._last_chunk, min(times), max(times))
                self._spans.append(span)
            span.first_ns = min(span.first_ns, min(times))
            span.last_ns = max(span.last_ns, max(times))

    def _learn_channels(self, handle: BinaryIO, channel_id: int) -> None:
        """The Channel records of the chunk naming `channel_id` first: that chunk's, or the one
        before (mcap closes a chunk that a Channel record filled before its first message)."""
        for offset in (self._last_chunk, self._previous_chunk):
            if offset is None or channel_id in self._channels:
                continue
            for record in self._chunk(handle, offset):
                if isinstance(record, Channel):
                    self._channels[record.id] = _map_topic(record)
        self._channels.setdefault(channel_id, None)  # not found: never looked for again

    def _chunk(self, handle: BinaryIO, offset: int) -> list[Any]:
        handle.seek(offset)
        opcode, length = _RECORD_HEADER.unpack(handle.read(_RECORD_HEADER.size))
        if opcode != Opcode.CHUNK or length > MAX_CHUNK_BYTES:
            raise SessionError(f"no readable chunk at byte {offset}")
        handle.seek(offset)
        chunk = _parsed(handle.read(_RECORD_HEADER.size + length))
        if not isinstance(chunk, Chunk):
            raise SessionError(f"no readable chunk at byte {offset}")
        self.chunks_decoded += 1
        return chunk_records(chunk)

    # -- reading a frame ----------------------------------------------------------------------

    def _messages(self, handle: BinaryIO, offset: int) -> list[tuple[TargetTopic, int, bytes]]:
        """(topic, log time, data) of the chunk's target messages, decoded once."""
        cached = self._decoded.get(offset)
        if cached is not None:
            self._decoded.move_to_end(offset)
            return cached
        records = self._chunk(handle, offset)
        for record in records:
            if isinstance(record, Channel) and record.id not in self._channels:
                self._channels[record.id] = _map_topic(record)
        messages = [
            (topic, record.log_time, bytes(record.data))
            for record in records
            if isinstance(record, Message)
            and (topic := self._channels.get(record.channel_id)) is not None
        ]
        self._decoded[offset] = messages
        if len(self._decoded) > CHUNKS_CACHED:
            self._decoded.popitem(last=False)
        return messages

    def _read(self, handle: BinaryIO, target_id: str, frame_index: int) -> FrameMaps:
        time_ns = frame_time_ns(frame_index, self.fps)
        signals: dict[str, Any] | None = None
        images: dict[TargetStream, bytes] = {}
        for span in self._spans:  # file order: a later record wins
            if not span.first_ns <= time_ns <= span.last_ns:
                continue
            for topic, log_time, data in self._messages(handle, span.offset):
                if log_time != time_ns or topic.target_id != target_id:
                    continue
                if topic.stream is TargetStream.SIGNALS:
                    signals = json.loads(data)
                else:
                    images[topic.stream] = data
        maps: dict[TargetStream, np.ndarray | None] = dict.fromkeys(MAP_STREAMS)
        for stream in MAP_STREAMS:
            limits = None if signals is None else signals.get(RANGE_FIELDS[stream])
            if limits is not None and stream in images:
                lo, hi = (none_to_nan(value) for value in limits)
                maps[stream] = recorded_map(stream, _mono8(json.loads(images[stream])), lo, hi)
        return FrameMaps(
            response=maps[TargetStream.RESPONSE],
            local_variation=maps[TargetStream.LOCAL_VARIATION],
            spatial_window=maps[TargetStream.SPATIAL_WINDOW],
        )


def _map_topic(channel: Channel) -> TargetTopic | None:
    """The target stream of a channel the maps are read from (signals and maps), else None."""
    topic = TargetTopic.parse(channel.topic)
    return None if topic is None or topic.stream is TargetStream.BOX else topic


def _parsed(data: bytes) -> Any:
    """The one record in `data` (its opcode, length and body), parsed by mcap."""
    reader = StreamReader(io.BytesIO(data), skip_magic=True, emit_chunks=True, validate_crcs=True)
    return next(iter(reader.records))


def _mono8(image: dict[str, Any]) -> np.ndarray:
    """The pixels of a foxglove.RawImage mono8 message."""
    pixels = np.frombuffer(base64.b64decode(image["data"]), dtype=np.uint8)
    pixels = pixels.reshape(int(image["height"]), int(image["step"]))
    return pixels[:, : int(image["width"])]
