"""Live input: a camera, a network stream or a video file played at its own frame rate, tracked
on the newest frame while older ones are dropped.

`LiveReader` runs a thread that takes frames from the source at the source's rate (a camera or
a stream delivers them as they come; a video file is paced to its frame rate, as a camera would
deliver it) and keeps only the newest one. The consumer asks for the next frame, gets the
newest captured since its last request, and every frame replaced before anyone took it is
recorded as dropped. The first frame is the exception: the initial boxes are drawn on it, so it
waits for the consumer and the frames arriving meanwhile are dropped instead. Each frame
carries its capture index (0-based, counting every frame the source delivered) and capture time
(seconds since the reader started, monotonic clock); the `LiveLog` records, per processed frame,
the latency from capture to result. `LiveFrames` shows the frames taken so far to the pipeline
as a growing FrameSource indexed by capture index (`autotrack.pipeline.live` runs it).
"""

from __future__ import annotations

import bisect
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from autotrack.errors import InputError
from autotrack.io.csv_table import write_csv
from autotrack.io.frames import FrameSource, open_local_video

STREAM_SCHEMES = ("rtsp://", "rtsps://", "http://", "https://", "udp://", "tcp://")
"""URL prefixes opened as network streams."""

OPEN_TIMEOUT_S = 10.0
"""How long to wait for the first frame of a camera or stream."""


def source_argument(text: str) -> Path | str:
    """Command-line SOURCE: a URL stays text (a Path would fold its '//'), the rest is a Path."""
    return text if text.lower().startswith(STREAM_SCHEMES) else Path(text)


def is_live_only(source: Path | str) -> bool:
    """True for a camera index or a stream URL (sources that cannot be read by index)."""
    return isinstance(source, str) or (str(source).isdigit() and not Path(source).exists())


def describe_source(source: Path | str) -> str:
    """'camera 0', the URL, or the file path: how messages name the source."""
    if isinstance(source, Path) and str(source).isdigit() and not source.exists():
        return f"camera {source}"
    return str(source)


@dataclass(frozen=True, eq=False)
class CapturedFrame:
    """One frame as the source delivered it."""

    index: int
    """0-based capture index: how many frames the source delivered before this one."""
    capture_time: float
    """Seconds from the reader's start to this frame's capture (monotonic clock)."""
    image: np.ndarray
    """RGB uint8 (H x W x 3)."""


def _open_capture(source: Path | str) -> tuple[cv2.VideoCapture, bool]:
    """An OpenCV capture of the source and whether it is a file to pace at its frame rate."""
    if isinstance(source, Path) and str(source).isdigit() and not source.exists():
        capture = cv2.VideoCapture(int(str(source)))
        is_file = False
    elif isinstance(source, Path):
        if not source.is_file():
            raise InputError(
                f"no such video file: {source} (--realtime reads a camera index, an rtsp:// or "
                "http:// stream, or a video file)"
            )
        capture = open_local_video(source)
        is_file = True
    else:
        capture = cv2.VideoCapture(source)
        is_file = False
    if not capture.isOpened():
        capture.release()
        raise InputError(f"cannot open {describe_source(source)} (unavailable or unsupported)")
    if not is_file:
        capture.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # fewer stale frames where the backend allows
    return capture, is_file


class LiveReader:
    """Reads a source in a background thread at the source's rate, keeping the newest frame.

    `fps` overrides the rate a video file is played at (default: its header's). `clock` and
    `sleep` are the time functions (monotonic seconds).
    """

    def __init__(
        self,
        source: Path | str,
        *,
        fps: float | None = None,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.source = source
        self._capture, self._paced = _open_capture(source)
        header_fps = float(self._capture.get(cv2.CAP_PROP_FPS) or 0.0)
        self.source_fps: float | None = (
            header_fps if np.isfinite(header_fps) and header_fps > 0 else None
        )
        """The frame rate the source announces (a video's header), None when it does not."""
        self.fps: float | None = fps or self.source_fps
        """The rate a video file is played at: `fps` if given, else its header's."""
        if self._paced and self.fps is None:
            raise InputError(f"{source} has no frame rate in its header: give --fps")
        self._clock, self._sleep = clock, sleep
        self._condition = threading.Condition()
        self._newest: CapturedFrame | None = None
        self._ended = False
        self._stop = False
        self._error: str | None = None
        self.captured = 0
        """Frames delivered by the source so far."""
        self.dropped: list[int] = []
        """Capture indices of the frames replaced by a newer one before being taken."""
        self.capture_times: list[float] = []
        """Capture time of every delivered frame, by capture index."""
        self.started_at = 0.0
        self._thread = threading.Thread(target=self._run, name="live-reader", daemon=True)

    @property
    def frame_size(self) -> tuple[int, int] | None:
        """(width, height) the source announces, or None when it does not say."""
        width = int(self._capture.get(cv2.CAP_PROP_FRAME_WIDTH) or 0)
        height = int(self._capture.get(cv2.CAP_PROP_FRAME_HEIGHT) or 0)
        return (width, height) if width > 0 and height > 0 else None

    def start(self) -> LiveReader:
        """Start reading (the capture clock starts now)."""
        self.started_at = self._clock()
        self._thread.start()
        return self

    def _run(self) -> None:
        try:
            while not self._stop:
                if self._paced:
                    due = self.started_at + self.captured / self.fps
                    delay = due - self._clock()
                    if delay > 0:
                        self._sleep(delay)
                ok, bgr = self._capture.read()
                if not ok or bgr is None:
                    break
                stamp = self._clock() - self.started_at
                rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB) if bgr.ndim == 3 else bgr
                with self._condition:
                    frame = CapturedFrame(self.captured, stamp, rgb)
                    self.capture_times.append(stamp)
                    self.captured += 1
                    if self._newest is not None and self._newest.index == 0:
                        self.dropped.append(frame.index)  # the first frame waits for its init
                    else:
                        if self._newest is not None:
                            self.dropped.append(self._newest.index)
                        self._newest = frame
                    self._condition.notify_all()
        except cv2.error as error:
            self._error = f"reading {describe_source(self.source)} failed: {error}"
        finally:
            with self._condition:
                self._ended = True
                self._condition.notify_all()

    def next_frame(self, timeout: float | None = OPEN_TIMEOUT_S) -> CapturedFrame | None:
        """The newest frame not yet taken, waiting for one; None when the source has ended.

        InputError when nothing arrives within `timeout` seconds or the source failed.
        """
        with self._condition:
            arrived = self._condition.wait_for(
                lambda: self._newest is not None or self._ended, timeout=timeout
            )
            if not arrived:
                raise InputError(
                    f"no frame from {describe_source(self.source)} within {timeout:g} s"
                )
            if self._error is not None:
                raise InputError(self._error)
            frame, self._newest = self._newest, None
            return frame

    def wait_until_captured(self, count: int, timeout: float | None = None) -> bool:
        """Block until the source has delivered `count` frames (or ended); True if it has."""
        with self._condition:
            self._condition.wait_for(lambda: self.captured >= count or self._ended, timeout)
            return self.captured >= count

    def now(self) -> float:
        """Seconds since the reader started, on the capture clock."""
        return self._clock() - self.started_at

    def close(self) -> None:
        """Stop the thread and release the source (left to the process's exit if a stalled
        stream keeps the thread in a read for longer than OPEN_TIMEOUT_S)."""
        self._stop = True
        if self._thread.is_alive():
            self._thread.join(timeout=OPEN_TIMEOUT_S)
        if not self._thread.is_alive():
            self._capture.release()

    def __enter__(self) -> LiveReader:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()


@dataclass(frozen=True)
class ProcessedFrame:
    """Timing of one frame that was processed."""

    index: int
    """Capture index."""
    capture_time: float
    """Seconds from the reader's start to the capture."""
    latency: float
    """Seconds from the capture to the result (waiting + tracking)."""


@dataclass(frozen=True)
class LiveSummary:
    """What a live run did with the frames its source delivered."""

    captured: int
    """Frames the source delivered."""
    capture_times: tuple[float, ...]
    """Capture time of every delivered frame (seconds from the reader's start)."""
    processed: tuple[ProcessedFrame, ...]
    """Frames processed, in order."""
    dropped: tuple[int, ...]
    """Capture indices of the frames never processed."""
    duration_s: float
    """Seconds from the reader's start to the last result."""

    @property
    def latencies_ms(self) -> np.ndarray:
        """Per processed frame, capture-to-result latency in milliseconds."""
        return np.array([frame.latency * 1e3 for frame in self.processed])

    def describe(self) -> str:
        """Two lines: frames captured/processed/dropped and the latency figures."""
        source_fps = self.captured / self.duration_s if self.duration_s > 0 else float("nan")
        lines = [
            f"live: {self.captured} frames captured ({source_fps:.1f} fps), "
            f"{len(self.processed)} processed, {len(self.dropped)} dropped"
            + (f" (frames {_ranges(self.dropped)})" if self.dropped else "")
        ]
        if self.processed:
            latency = self.latencies_ms
            lines.append(
                f"latency capture -> result: median {np.median(latency):.1f} ms, "
                f"95th percentile {np.percentile(latency, 95):.1f} ms, max {latency.max():.1f} ms"
            )
        return "\n".join(lines)


def _ranges(indices: Sequence[int], limit: int = 12) -> str:
    """'3, 5-7, 9' (first `limit` runs, then '...')."""
    runs: list[list[int]] = []
    for index in indices:
        if runs and index == runs[-1][1] + 1:
            runs[-1][1] = index
        else:
            runs.append([index, index])
    text = [f"{a}" if a == b else f"{a}-{b}" for a, b in runs[:limit]]
    return ", ".join(text) + (", ..." if len(runs) > limit else "")


class LiveLog:
    """Pairs each processed frame with its result time; summarises drops and latency."""

    def __init__(self, reader: LiveReader) -> None:
        self.reader = reader
        self.processed: list[ProcessedFrame] = []
        self._pending: list[CapturedFrame] = []
        self._last_result = 0.0

    def frames(self) -> Iterator[CapturedFrame]:
        """The newest frame each time the consumer is ready, until the source ends."""
        while (frame := self.reader.next_frame()) is not None:
            self._pending.append(frame)
            yield frame

    def adopt(self, frame: CapturedFrame) -> None:
        """Count a frame taken from the reader outside `frames()` (a preview frame the targets
        were drawn on) as processed now; its latency includes the time spent drawing."""
        self._pending.append(frame)
        self.result_ready()

    def result_ready(self) -> CapturedFrame:
        """Mark the oldest frame handed out and not yet finished as done now; returns it."""
        frame = self._pending.pop(0)
        self._last_result = self.reader.now()
        latency = self._last_result - frame.capture_time
        self.processed.append(ProcessedFrame(frame.index, frame.capture_time, latency))
        return frame

    def summary(self) -> LiveSummary:
        """Frames captured, processed and dropped so far."""
        done = {frame.index for frame in self.processed}
        dropped = tuple(index for index in range(self.reader.captured) if index not in done)
        return LiveSummary(
            self.reader.captured,
            tuple(self.reader.capture_times),
            tuple(self.processed),
            dropped,
            self._last_result,
        )


def write_frame_log(path: str | Path, summary: LiveSummary) -> Path:
    """CSV, one row per captured frame: frame (capture index), capture_time_s, processed (0/1),
    latency_ms (capture to result; empty for dropped frames)."""
    path = Path(path)
    by_index = {frame.index: frame for frame in summary.processed}
    rows = []
    for index, capture_time in enumerate(summary.capture_times):
        frame = by_index.get(index)
        latency = "" if frame is None else f"{frame.latency * 1e3:.3f}"
        rows.append([index, f"{capture_time:.6f}", int(frame is not None), latency])
    header = ["frame", "capture_time_s", "processed", "latency_ms"]
    return write_csv(path, header, rows, line_end="\r\n")


class LiveFrames(FrameSource):
    """The frames taken from a live source, as a FrameSource indexed by capture index.

    It grows as frames are taken (`take`): its length is the last taken capture index + 1.
    Only the last `keep` taken frames can be read (the dropped ones never could), and
    `previous_index` skips the dropped frames, so the pipeline tracks from one taken frame to
    the next.
    """

    live = True

    def __init__(self, name: str, fps: float | None, keep: int = 8) -> None:
        self.name = name
        self.fps = fps
        self.keep = keep
        self._count = 0
        self._taken: list[int] = []
        self._images: OrderedDict[int, np.ndarray] = OrderedDict()

    def take(self, frame: CapturedFrame) -> None:
        """Add a frame handed out by the reader (capture indices increase)."""
        if self._taken and frame.index <= self._taken[-1]:
            raise InputError(f"frame {frame.index} taken after frame {self._taken[-1]}")
        self._taken.append(frame.index)
        self._count = frame.index + 1
        self._images[frame.index] = frame.image
        while len(self._images) > self.keep:
            self._images.popitem(last=False)

    def __len__(self) -> int:
        return self._count

    @property
    def frame_size(self) -> tuple[int, int]:
        """(width, height) of the taken frames."""
        if not self._images:
            raise InputError(f"{self.name}: no frame taken yet")
        height, width = next(iter(self._images.values())).shape[:2]
        return (width, height)

    def previous_index(self, index: int) -> int:
        """The taken frame before `index` (-1 before the first)."""
        position = bisect.bisect_left(self._taken, index)
        return self._taken[position - 1] if position > 0 else -1

    def read(self, index: int) -> np.ndarray:
        image = self._images.get(self._check_index(index))
        if image is None:
            raise InputError(f"frame {index} of {self.name} was dropped or is no longer kept")
        return image

    def _read_bgr(self, index: int) -> np.ndarray:
        image = self.read(index)
        return cv2.cvtColor(image, cv2.COLOR_RGB2BGR) if image.ndim == 3 else image

    def close(self) -> None:
        """Forget the kept frames (the reader is closed by its owner)."""
        self._images.clear()
