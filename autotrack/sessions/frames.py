"""The video frames a session embeds (`embed_frames`, the default for a pipeline's recording),
read back as a FrameSource, so a recorded run can be reopened and looked through although its
source cannot be replayed (a live run) or is gone, and written back out as image files.

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

import numpy as np
from mcap.records import Channel, Message

from autotrack.errors import InputError, SessionError
from autotrack.io.frames import EncodedFrame, FrameSource, decode_image
from autotrack.sessions.limits import DECODE_ERRORS
from autotrack.sessions.records import iter_records, scan_records
from autotrack.sessions.schemas import Topics
from autotrack.sessions.session import Session

FILE_SUFFIXES = {"jpeg": ".jpg", "png": ".png"}
"""The file suffix of each embedded image format."""


def embedded_images(path: Path) -> dict[int, EncodedFrame]:
    """Log time (ns) -> encoded image of every embedded frame (also from a file cut short)."""
    images: dict[int, EncodedFrame] = {}
    image_channels: set[int] = set()
    with open(path, "rb") as handle:
        limit, _complete = scan_records(handle, os.fstat(handle.fileno()).st_size, str(path))
        try:
            for record in iter_records(handle, limit):
                if isinstance(record, Channel) and record.topic == Topics.IMAGE.name:
                    image_channels.add(record.id)
                elif isinstance(record, Message) and record.channel_id in image_channels:
                    payload = json.loads(record.data)
                    data = base64.b64decode(payload["data"])
                    images[record.log_time] = EncodedFrame(data, str(payload["format"]))
        except DECODE_ERRORS as error:
            raise SessionError(f"{path} is corrupted ({type(error).__name__}: {error})") from error
    return images


def frames_by_index(session: Session) -> dict[int, EncodedFrame]:
    """Frame index -> encoded image of every frame `session` embeds, in frame order."""
    images = embedded_images(session.path)
    by_frame = {round(t * session.fps / 1e9): image for t, image in sorted(images.items())}
    return dict(sorted(by_frame.items()))


def write_frames(session: Session, folder: Path, *, force: bool = False) -> int:
    """Write the embedded frames to `folder` as image files, their bytes as recorded (no
    re-encoding): `000001.jpg`, ... numbered from 1 by frame (a dropped live frame leaves a
    gap), so the folder is a sequence `autotrack track` reads and the OTB export's row i is
    file i. Existing files are kept unless `force`. Returns the number of files written."""
    images = frames_by_index(session)
    if not images:
        raise InputError(f"{session.path.name} embeds no video frames (recorded with --no-frames)")
    names = {
        index: f"{index + 1:06d}{FILE_SUFFIXES.get(image.format, '.' + image.format)}"
        for index, image in images.items()
    }
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"cannot create folder {folder}: {error.strerror}") from error
    taken = [name for name in names.values() if (folder / name).exists()]
    if taken and not force:
        raise InputError(f"{folder / taken[0]} exists (use --force to replace the frames)")
    for index, image in images.items():
        try:
            (folder / names[index]).write_bytes(image.data)
        except OSError as error:
            raise InputError(f"cannot write {folder / names[index]}: {error.strerror}") from error
    return len(images)


class EmbeddedFrames(FrameSource):
    """The frames embedded in a session, indexed as the session indexes them."""

    independent_reads = True  # each read decodes its own encoded bytes

    def __init__(self, session: Session) -> None:
        self.name = Path(session.source).name or str(session.source)
        self.fps = session.fps
        by_frame = frames_by_index(session)
        if not by_frame:
            raise InputError(
                f"{session.path.name} embeds no video frames (recorded with --no-frames)"
            )
        self._indices = sorted(by_frame)
        self._images = by_frame
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

    def _recorded(self, index: int) -> int:
        position = bisect.bisect_right(self._indices, index)
        return self._indices[max(position - 1, 0)]  # a dropped frame: the last one before

    def encoded(self, index: int) -> EncodedFrame | None:
        """The frame's image as the session holds it (a resumed recording embeds it again)."""
        image = self._images[self._recorded(self._check_index(index))]
        return image if image.format in FILE_SUFFIXES else None

    def _read_bgr(self, index: int) -> np.ndarray:
        recorded = self._recorded(index)
        data = np.frombuffer(self._images[recorded].data, np.uint8)
        image = decode_image(data, bgr=True)
        if image is None:
            raise SessionError(f"frame {recorded} embedded in {self.name} cannot be decoded")
        return image

    def close(self) -> None:
        """Nothing is held open (the encoded frames are in memory)."""
