"""Several independent AutoTrack targets on the same frames.

Each target has its own AutoTrack (its own filter, scale filter and regularisation state); the
frame is decoded and checked once and handed to every tracker, optionally on a thread pool
(numpy, scipy.fft, OpenCV and numba release the GIL in the heavy parts). Every result carries
the multi-tracker's frame index, so a target added or reset later is numbered like the others.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np

from autotrack.errors import InputError
from autotrack.params import TrackerParams
from autotrack.result import TrackResult
from autotrack.tracker.tracker import AutoTrack

Box = Sequence[float]


class MultiTracker:
    """N named AutoTrack targets fed with one shared frame per step."""

    def __init__(
        self,
        params: TrackerParams,
        target_ids: Iterable[str] = (),
        threads: int = 1,
        colour_table: np.ndarray | None = None,
    ) -> None:
        """`target_ids` fixes the targets `init` expects (empty: whatever `init` is given);
        `threads` > 1 runs the targets concurrently."""
        if threads < 1:
            raise InputError(f"threads must be at least 1, got {threads}")
        self.params = params
        self.colour_table = colour_table
        self.threads = threads
        self._expected = tuple(target_ids)
        self._trackers: dict[str, AutoTrack] = {}
        self._frame_index = -1
        self._pool = ThreadPoolExecutor(max_workers=threads) if threads > 1 else None

    @property
    def target_ids(self) -> tuple[str, ...]:
        """Targets currently tracked, in the order they were added."""
        return tuple(self._trackers)

    @property
    def frame_index(self) -> int:
        """0-based index of the last frame processed (-1 before `init`)."""
        return self._frame_index

    def init(self, frame: np.ndarray, boxes: Mapping[str, Box]) -> dict[str, TrackResult]:
        """Start every target on `frame` (frame index 0) from its (x, y, w, h) box."""
        if self._expected and set(boxes) != set(self._expected):
            missing = sorted(set(self._expected) - set(boxes))
            extra = sorted(set(boxes) - set(self._expected))
            detail = "; ".join(
                part
                for part in (
                    f"missing {', '.join(missing)}" if missing else "",
                    f"unexpected {', '.join(extra)}" if extra else "",
                )
                if part
            )
            raise InputError(f"initial boxes do not match the targets ({detail})")
        if not boxes:
            raise InputError("no targets to track: give at least one box")
        frame = _shared_frame(frame)
        self._trackers = {str(k): self._new_tracker() for k in boxes}
        self._frame_index = 0
        starts = {str(k): tuple(b) for k, b in boxes.items()}
        return self._run(lambda target_id, tracker: tracker.init(frame, starts[target_id]))

    def update(self, frame: np.ndarray) -> dict[str, TrackResult]:
        """Track every target into the next frame."""
        if self._frame_index < 0:
            raise InputError("call init(frame, boxes) before update(frame)")
        frame = _shared_frame(frame)
        self._frame_index += 1
        return self._run(lambda _target_id, tracker: tracker.update(frame))

    def add_target(self, target_id: str, frame: np.ndarray, box: Box) -> TrackResult:
        """Start a new target on `frame`, which must be the frame last processed."""
        if target_id in self._trackers:
            raise InputError(f"target {target_id!r} already exists; use reset_target to move it")
        return self._start(target_id, frame, box)

    def remove_target(self, target_id: str) -> None:
        """Stop tracking a target."""
        if target_id not in self._trackers:
            raise InputError(f"no target {target_id!r} (targets: {', '.join(self._trackers)})")
        del self._trackers[target_id]

    def reset_target(self, target_id: str, frame: np.ndarray, box: Box) -> TrackResult:
        """Restart a target from a corrected box on `frame` (the frame last processed), e.g. when
        a user fixes a drifting box; the other targets are untouched."""
        if target_id not in self._trackers:
            raise InputError(f"no target {target_id!r} (targets: {', '.join(self._trackers)})")
        return self._start(target_id, frame, box)

    def close(self) -> None:
        """Stop the worker threads (the trackers' state stays readable)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def __enter__(self) -> MultiTracker:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- internals --------------------------------------------------------------------------

    def _new_tracker(self) -> AutoTrack:
        return AutoTrack(self.params, colour_table=self.colour_table)

    def _start(self, target_id: str, frame: np.ndarray, box: Box) -> TrackResult:
        if self._frame_index < 0:
            raise InputError("call init(frame, boxes) before adding or resetting a target")
        tracker = self._new_tracker()
        result = tracker.init(_shared_frame(frame), tuple(box))
        self._trackers[target_id] = tracker
        return replace(result, frame_index=self._frame_index)

    def _run(self, step: Callable[[str, AutoTrack], TrackResult]) -> dict[str, TrackResult]:
        """Apply `step` to every (target id, tracker), concurrently when there is a pool."""
        items = list(self._trackers.items())
        if self._pool is None or len(items) < 2:
            results = {k: step(k, tracker) for k, tracker in items}
        else:
            futures = {k: self._pool.submit(step, k, tracker) for k, tracker in items}
            results = {k: future.result() for k, future in futures.items()}
        return {k: replace(r, frame_index=self._frame_index) for k, r in results.items()}


def _shared_frame(frame: np.ndarray) -> np.ndarray:
    """One contiguous, read-only uint8 array that every tracker can read without copying."""
    if not isinstance(frame, np.ndarray) or frame.ndim not in (2, 3) or frame.size == 0:
        raise InputError("a frame must be a non-empty HxW or HxWx3 numpy array")
    if frame.dtype != np.uint8:
        frame = np.clip(frame, 0, 255).astype(np.uint8)
    frame = np.ascontiguousarray(frame)
    if frame.flags.writeable:
        frame = frame.view()
        frame.flags.writeable = False
    return frame
