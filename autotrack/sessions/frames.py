"""The video frames a session embeds (`embed_frames=True`, as live runs record them), read back
as a FrameSource, so a recorded live run can be reopened and looked through although its
source cannot be replayed.

Frames are numbered as the session numbers them (a live run's capture indices). A frame the
run dropped was never recorded: reading it gives the last recorded frame before it, and
`previous_index` skips it, as `autotrack.io.live.LiveFrames` does during the run.
"""

from __future__ import annotations

import base64
import bisect
import json
import os
from pathlib import Path

import cv2
import numpy as np
from mcap.records import Channel, Message

from autotrack.errors import InputError, SessionError
from autotrack.io.frames import FrameSource
from autotrack.sessions.limits import DECODE_ERRORS
from autotrack.sessions.records import iter_records, scan_records
from autotrack.sessions.schemas import Topics
from autotrack.sessions.session import Session


def _embedded_jpegs(path: Path) -> dict[int, bytes]:
    """Log time (ns) -> encoded image of every embedded frame (also from a file cut short)."""
    images: dict[int, bytes] = {}
    image_channels: set[int] = set()
    with open(path, "rb") as handle:
        limit, _complete = scan_records(handle, os.fstat(handle.fileno()).st_size, str(path))
        try:
            for record in iter_records(handle, limit):
                if isinstance(record, Channel) and record.topic == Topics.IMAGE.name:
                    image_channels.add(record.id)
                elif isinstance(record, Message) and record.channel_id in image_channels:
                    payload = json.loads(record.data)
                    images[record.log_time] = base64.b64decode(payload["data"])
        except DECODE_ERRORS as error:
            raise SessionError(f"{path} is corrupted ({type(error).__name__}: {error})") from error
    return images


class EmbeddedFrames(FrameSource):
    """The frames embedded in a session, indexed as the session indexes them."""

    independent_reads = True  # each read decodes its own JPEG bytes

    def __init__(self, session: Session) -> None:
        self.name = Path(session.source).name or str(session.source)
        self.fps = session.fps
        jpegs = _embedded_jpegs(session.path)
        if not jpegs:
            raise InputError(
                f"{session.path.name} embeds no video frames (only live runs record them)"
            )
        by_frame = {round(time_ns * session.fps / 1e9): data for time_ns, data in jpegs.items()}
        self._indices = sorted(by_frame)
        self._jpegs = by_frame
        self._count = max(self._indices[-1] + 1, session.frame_count)

    @property
    def recorded_indices(self) -> tuple[int, ...]:
        """The frames whose image the session holds (the processed ones), in order."""
        return tuple(self._indices)

    def __len__(self) -> int:
        return self._count

    def previous_index(self, index: int) -> int:
        """The recorded frame before `index` (-1 before the first)."""
        position = bisect.bisect_left(self._indices, index)
        return self._indices[position - 1] if position > 0 else -1

    def _read_bgr(self, index: int) -> np.ndarray:
        position = bisect.bisect_right(self._indices, index)
        recorded = self._indices[max(position - 1, 0)]  # a dropped frame: the last one before
        image = cv2.imdecode(np.frombuffer(self._jpegs[recorded], np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise SessionError(f"frame {recorded} embedded in {self.name} cannot be decoded")
        return image

    def close(self) -> None:
        """Nothing is held open (the encoded frames are in memory)."""
