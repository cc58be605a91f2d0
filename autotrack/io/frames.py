"""Frame sources: a folder of images, a benchmark sequence folder or a video file, read by index.

Every source returns RGB uint8 frames (H x W x 3), or H x W for single-channel image files;
`read_bgr` gives OpenCV's channel order for OpenCV trackers. Image folders are read in plain
sorted file-name order (benchmark frames are zero-padded, so that is frame order). Videos are
decoded sequentially: reading forward is one decode per frame, a small cache serves short
backward steps, and a longer backward jump re-opens the video and decodes from the start
(exact for every codec, unlike container seeking).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from abc import ABC, abstractmethod
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import cv2
import numpy as np

from autotrack.errors import InputError
from autotrack.io.jpeg import decode_jpeg

IMAGE_EXTENSIONS = frozenset({".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp"})
"""File extensions (lower case) read as frames."""
VIDEO_EXTENSIONS = frozenset(
    {".mp4", ".m4v", ".mov", ".avi", ".mkv", ".webm", ".mpg", ".mpeg", ".ts", ".wmv", ".flv"}
)
"""Video container extensions (lower case) opened as videos; any other file is refused (FFmpeg
would otherwise open a text file as a playlist)."""
VIDEO_DEMUXERS = (
    "mov,mp4,m4a,3gp,3g2,mj2",
    "m4v",
    "avi",
    "matroska,webm",
    "mpeg",
    "mpegts",
    "asf",
    "flv",
)
"""The FFmpeg demuxers a local video may be read with: containers only, so no playlist (hls),
concat list or image pattern can make FFmpeg open files outside the allowed folders."""
LOCAL_CAPTURE_OPTIONS = "protocol_whitelist;file|format_whitelist;" + ",".join(VIDEO_DEMUXERS)
"""FFmpeg options for local video files (OpenCV reads OPENCV_FFMPEG_CAPTURE_OPTIONS when it
opens a capture): the file protocol only, and the demuxers above."""
_CAPTURE_OPTIONS = "OPENCV_FFMPEG_CAPTURE_OPTIONS"
_CAPTURE_OPTIONS_LOCK = threading.Lock()

VIDEO_CACHE_FRAMES = 16
"""Decoded video frames kept for backward steps without re-decoding."""
_FILE_SIGNATURES = {b"\xff\xd8\xff": "jpeg", b"\x89PNG\r\n\x1a\n": "png"}
"""The first bytes of the encoded formats a frame is embedded in as it is (`EncodedFrame`)."""


@dataclass(frozen=True)
class EncodedFrame:
    """A frame as its file holds it, in a format any image viewer decodes."""

    data: bytes
    """The file's bytes."""
    format: str
    """"jpeg" or "png" (told by the bytes, not by the file name)."""

    @classmethod
    def of(cls, data: bytes) -> EncodedFrame | None:
        """`data` as an EncodedFrame when it is JPEG or PNG, else None."""
        for signature, image_format in _FILE_SIGNATURES.items():
            if data.startswith(signature):
                return cls(data, image_format)
        return None


def _frame_label(index: int) -> str:
    return f"frame {index} (0-based; frame {index + 1} counting from 1)"


def list_image_files(folder: Path) -> list[Path]:
    """The image files directly inside `folder`, in sorted name order."""
    return sorted(
        entry
        for entry in folder.iterdir()
        if entry.is_file() and entry.suffix.lower() in IMAGE_EXTENSIONS
    )


def open_local_video(path: Path) -> cv2.VideoCapture:
    """An OpenCV (FFmpeg) capture of a local video file that reads that file only: a known
    container extension, FFmpeg restricted to the file protocol and container demuxers."""
    if path.suffix.lower() not in VIDEO_EXTENSIONS:
        known = ", ".join(sorted(VIDEO_EXTENSIONS))
        raise InputError(f"{path.name}: not a video file this tool reads ({known})")
    # The options are read from the environment as the capture opens; the lock keeps another
    # thread's capture (a stream, which needs other protocols) from seeing them.
    with _CAPTURE_OPTIONS_LOCK:
        previous = os.environ.get(_CAPTURE_OPTIONS)
        os.environ[_CAPTURE_OPTIONS] = LOCAL_CAPTURE_OPTIONS
        try:
            return cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
        finally:
            if previous is None:
                del os.environ[_CAPTURE_OPTIONS]
            else:
                os.environ[_CAPTURE_OPTIONS] = previous


def read_image(path: Path, index: int | None = None, *, bgr: bool = False) -> np.ndarray:
    """Decode one image file as uint8: RGB (or BGR), or 2-D for single-channel files.

    `index` is only used to name the frame in the error message.
    """
    label = f"{_frame_label(index)}: " if index is not None else ""
    try:
        encoded = np.fromfile(path, dtype=np.uint8)
    except OSError as error:
        raise InputError(f"{label}cannot read image file {path}: {error.strerror}") from error
    image = decode_image(encoded, bgr=bgr)
    if image is None:
        raise InputError(f"{label}cannot decode image file {path} (corrupt or not an image)")
    return image


def decode_image(encoded: np.ndarray, *, bgr: bool = False) -> np.ndarray | None:
    """Decode an encoded image (uint8 bytes) as a frame source reads its files: uint8 RGB (or
    BGR), 2-D for single-channel images; None when it does not decode."""
    image = decode_jpeg(encoded, bgr=bgr)  # OpenCV's pixels, faster, already in order
    if image is not None:
        return image
    image = cv2.imdecode(encoded, cv2.IMREAD_ANYCOLOR) if encoded.size else None
    if image is None:
        return None
    if image.ndim == 3 and not bgr:
        # In place, on the array just decoded: the same pixels as a converted copy, without
        # allocating (and page-faulting in) a second frame: ~1.6 ms of CPU a 1280x720 frame.
        cv2.cvtColor(image, cv2.COLOR_BGR2RGB, dst=image)
    return image


class FrameSource(ABC):
    """Frames of one sequence, read by 0-based index."""

    name: str
    """Short name of the source (folder or file stem)."""
    fps: float | None
    """Frame rate from the video header; None for image folders."""
    independent_reads: bool = False
    """Reading a frame touches no state another read uses, so `FrameCache` may decode the next
    frames on background threads, several at once (not a video: its decoder reads in order)."""
    live: bool = False
    """Frames of a live source (a camera, a stream), which cannot be read again later."""

    @abstractmethod
    def __len__(self) -> int:
        """Number of frames."""

    @abstractmethod
    def _read_bgr(self, index: int) -> np.ndarray:
        """Decode frame `index` (already checked to be in range) in BGR order."""

    def _check_index(self, index: int) -> int:
        count = len(self)
        if not -count <= index < count:
            raise IndexError(f"frame index {index} out of range for {count} frames of {self.name}")
        return index % count

    def read_bgr(self, index: int) -> np.ndarray:
        """Frame `index` (0-based) in OpenCV's BGR order (2-D for single-channel images)."""
        return self._read_bgr(self._check_index(index))

    def read(self, index: int) -> np.ndarray:
        """Frame `index` (0-based) as RGB uint8 (2-D for single-channel images)."""
        frame = self.read_bgr(index)
        return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB) if frame.ndim == 3 else frame

    @cached_property
    def frame_size(self) -> tuple[int, int]:
        """(width, height) of the first frame in pixels."""
        height, width = self.read_bgr(0).shape[:2]
        return (width, height)

    def previous_index(self, index: int) -> int:
        """The frame tracked before frame `index`: `index - 1` (a live source skips the frames
        it dropped)."""
        return index - 1

    def encoded(self, index: int) -> EncodedFrame | None:
        """Frame `index` as its file holds it when that is a JPEG or PNG file (a recording
        embeds those bytes as they are), else None (the frame is only available decoded)."""
        self._check_index(index)
        return None

    def __iter__(self) -> Iterator[np.ndarray]:
        for index in range(len(self)):
            yield self.read(index)

    @abstractmethod
    def close(self) -> None:
        """Release any open file handle."""

    def __enter__(self) -> FrameSource:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class ImageSequence(FrameSource):
    """Frames stored as one image file each."""

    independent_reads = True

    def __init__(self, paths: Sequence[Path], name: str) -> None:
        if not paths:
            raise InputError(f"{name}: no image frames")
        self.paths: tuple[Path, ...] = tuple(Path(p) for p in paths)
        self.name = name
        self.fps = None

    def __len__(self) -> int:
        return len(self.paths)

    def _read_bgr(self, index: int) -> np.ndarray:
        return read_image(self.paths[index], index, bgr=True)

    def read(self, index: int) -> np.ndarray:
        """Frame `index` (0-based) as RGB uint8 (2-D for single-channel images), converted in
        place as it is decoded (`read_image`)."""
        index = self._check_index(index)
        return read_image(self.paths[index], index)

    def encoded(self, index: int) -> EncodedFrame | None:
        """The frame's file as it is, when it is JPEG or PNG (None for BMP, TIFF, WebP)."""
        path = self.paths[self._check_index(index)]
        try:
            data = path.read_bytes()
        except OSError as error:
            raise InputError(
                f"{_frame_label(index)}: cannot read image file {path}: {error.strerror}"
            ) from error
        return EncodedFrame.of(data)

    def close(self) -> None:
        """Nothing to release: each read opens and closes its file."""


class InMemoryFrames(FrameSource):
    """Frames already decoded (RGB or grey uint8 arrays), e.g. rendered or edited in memory."""

    def __init__(self, frames: Sequence[np.ndarray], name: str, fps: float | None = None) -> None:
        if not frames:
            raise InputError(f"{name}: no frames")
        self.frames = list(frames)
        self.name = name
        self.fps = fps

    def __len__(self) -> int:
        return len(self.frames)

    def read(self, index: int) -> np.ndarray:
        return self.frames[self._check_index(index)]

    def _read_bgr(self, index: int) -> np.ndarray:
        frame = self.frames[index]
        return cv2.cvtColor(frame, cv2.COLOR_RGB2BGR) if frame.ndim == 3 else frame

    def close(self) -> None:
        """Nothing to release."""


class VideoFrames(FrameSource):
    """Frames decoded from a video file by OpenCV, in order, with a small cache."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.name = path.stem
        self._capture = self._open()
        self._count = int(self._capture.get(cv2.CAP_PROP_FRAME_COUNT))
        fps = float(self._capture.get(cv2.CAP_PROP_FPS))
        self.fps = fps if np.isfinite(fps) and fps > 0 else None
        self._next_index = 0
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()
        if self._count <= 0 or not self._last_frame_decodes():
            self._count = self._count_by_decoding()

    def _open(self) -> cv2.VideoCapture:
        capture = open_local_video(self.path)
        if not capture.isOpened():
            capture.release()
            raise InputError(f"cannot open video {self.path} (unsupported format or corrupt file)")
        return capture

    def _last_frame_decodes(self) -> bool:
        """Whether the frame the header announces last is there (a cut or badly muxed file
        announces more frames than it holds: playing it would fail before its end)."""
        self._capture.set(cv2.CAP_PROP_POS_FRAMES, self._count - 1)
        there = self._capture.grab()
        self._rewind()
        return there

    def _count_by_decoding(self) -> int:
        count = 0
        while self._capture.grab():
            count += 1
        self._rewind()
        if count == 0:
            raise InputError(f"video {self.path} has no decodable frames")
        return count

    def _rewind(self) -> None:
        self._capture.release()
        self._capture = self._open()
        self._next_index = 0

    def __len__(self) -> int:
        return self._count

    def _read_bgr(self, index: int) -> np.ndarray:
        if index in self._cache:
            self._cache.move_to_end(index)
            return self._cache[index]
        if index < self._next_index:
            self._rewind()
        while self._next_index < index:
            if not self._capture.grab():
                break
            self._next_index += 1
        ok, frame = self._capture.read() if self._next_index == index else (False, None)
        if not ok or frame is None:
            raise InputError(
                f"{_frame_label(index)}: cannot decode from video {self.path} "
                f"(the header announces {self._count} frames)"
            )
        self._next_index = index + 1
        self._cache[index] = frame
        if len(self._cache) > VIDEO_CACHE_FRAMES:
            self._cache.popitem(last=False)
        return frame

    def close(self) -> None:
        self._capture.release()
        self._cache.clear()


def open_frames(path: str | Path) -> FrameSource:
    """Open a folder of images, a benchmark sequence folder (with `img/`), an image or a video.

    Raises InputError for a missing path, a folder without images, or a video OpenCV cannot
    open. Corrupt image files are reported when read, naming the frame and the file.
    """
    path = Path(path).expanduser()
    if not path.exists():
        raise InputError(f"no such file or folder: {path}")
    if path.is_dir():
        image_folder = path / "img" if (path / "img").is_dir() else path
        paths = list_image_files(image_folder)
        if not paths:
            extensions = ", ".join(sorted(IMAGE_EXTENSIONS))
            raise InputError(f"no image files ({extensions}) in folder {image_folder}")
        return ImageSequence(paths, path.name)
    if path.suffix.lower() in IMAGE_EXTENSIONS:
        return ImageSequence([path], path.stem)
    return VideoFrames(path)


class FrameCache:
    """The last few frames read from a FrameSource, for stepping back and forth without
    decoding again.

    Reading frames in order from a source whose reads are independent (image files) reads the
    next `READ_AHEAD_FRAMES` frames on background threads meanwhile (`prefetch`; the decoders
    release the GIL, so a frame is ready when the trackers of the frame before are done): the
    caller gets the same frames in the same order, and a frame that cannot be read raises the
    source's own error when the caller asks for it, as without prefetching; a jump drops the
    frames read ahead. `READ_AHEAD_THREADS` threads ("prefetch") serve every read-ahead of the
    cache, started on the first and stopped by `close` (or when the cache is garbage-collected);
    a thread per frame cost the caller ~0.1 ms a frame to start. They run at a low priority
    (`READ_AHEAD_NICENESS`): with tracking processes on every core they decode in their idle
    time instead of slowing them down, and several frames ahead on two threads they can use
    idle time wherever and on whichever core it falls, not only in the one frame's time before
    that frame is needed.
    """

    def __init__(self, frames: FrameSource, size: int, *, prefetch: bool = True) -> None:
        self.frames = frames
        self.size = size
        self.prefetch = prefetch and frames.independent_reads
        self._cached: OrderedDict[int, np.ndarray] = OrderedDict()
        self._reader: ThreadPoolExecutor | None = None
        self._pending: dict[int, Future[np.ndarray]] = {}
        self._last_read = -2

    def read(self, index: int) -> np.ndarray:
        """Frame `index` (RGB uint8); InputError outside the sequence."""
        if not 0 <= index < len(self.frames):
            raise InputError(f"frame {index} is outside 0..{len(self.frames) - 1}")
        cached = self._cached.get(index)
        if cached is not None:
            self._cached.move_to_end(index)
            return cached
        image = self._prefetched(index)
        if image is None:
            image = self.frames.read(index)
        # Read-only: every caller shares the cached array (and a tracker that speculated on it
        # trusts that it does not change, `autotrack.tracker.parallel.speculation`).
        image.flags.writeable = False
        self._cached[index] = image
        if len(self._cached) > self.size:
            self._cached.popitem(last=False)
        if self.prefetch and index == self._last_read + 1:
            if self._reader is None:
                self._reader = ThreadPoolExecutor(
                    max_workers=READ_AHEAD_THREADS,
                    thread_name_prefix="prefetch",
                    initializer=_yield_to_trackers,
                )
            last = min(index + READ_AHEAD_FRAMES, len(self.frames) - 1)
            for following in range(index + 1, last + 1):
                if following not in self._pending and following not in self._cached:
                    self._pending[following] = self._reader.submit(self.frames.read, following)
        self._last_read = index
        return image

    def _prefetched(self, index: int) -> np.ndarray | None:
        """The frame read ahead when it is `index`, else None (not read ahead, or the read
        failed: the caller reads it again and gets the source's own error). A jump drops the
        other frames read ahead."""
        future = self._pending.pop(index, None)
        if future is None or index != self._last_read + 1:
            self._drop_read_ahead()  # a jump: the others are not needed next after all
            if future is None:
                return None
        try:
            return future.result()
        except Exception:  # noqa: BLE001 - read again by the caller, which reports the error
            return None

    def close(self) -> None:
        """Stop the read-ahead threads (after the reads in progress); reads go on without them."""
        self.prefetch = False
        self._drop_read_ahead()
        if self._reader is not None:
            self._reader.shutdown(wait=True)
            self._reader = None

    def _drop_read_ahead(self) -> None:
        """Forget every frame read ahead; those not started yet are not read at all."""
        for future in self._pending.values():
            future.cancel()
        self._pending.clear()


READ_AHEAD_FRAMES = 3
"""Frames a `FrameCache` decodes ahead of the caller: with two tracking processes on two cores,
three let the decoding fill idle time that one frame ahead leaves unused (71.1 against 69.7
frames/s, docs/history.md, round 19); six gave no more."""

READ_AHEAD_THREADS = 2
"""Threads decoding the frames read ahead: two can fill idle time on both cores at once
(71.2 -> 73.9 frames/s with two tracking processes; one thread tracking: no change; three:
72.9 against 74.0)."""

READ_AHEAD_NICENESS = 19
"""Scheduling niceness of the read-ahead threads (Linux: per thread): they decode on a core the
trackers leave idle rather than taking turns with them (docs/benchmarks.md, Speed)."""


def _yield_to_trackers() -> None:
    """Lower the calling thread's scheduling priority to `READ_AHEAD_NICENESS`, where the
    system allows it (a caller waiting for its frame leaves a core idle, where it runs)."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError):
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), READ_AHEAD_NICENESS)
