"""Several independent AutoTrack targets on the same frames.

Each target has its own AutoTrack (its own filter, scale filter and regularisation state); the
frame is decoded and checked once and handed to every tracker, optionally on a thread pool
(numpy, scipy.fft, OpenCV and numba release the GIL in the heavy parts) and optionally shared
with child processes (`processes` > 1: the targets are spread over this process and
`processes - 1` children, `target_process`, which gives true parallelism where threads
serialise on the GIL). Every result carries the multi-tracker's frame index, so a target added
or reset later is numbered like the others.

Speculation: a caller that knows the frame the next `update` will get passes it along
(`update(frame, next_frame)`, called before this process's targets are tracked; or `speculate`
between two calls). The children queue it behind the frame they are tracking, so they never
wait for this process while it tracks its own targets, collects their answers, stores results,
solves the pose and reads the next frame; the next `update` with that frame (the same array,
or equal values) collects their answers without sending anything.
Each child copies the trackers it updates speculatively first (`target_process`); any other
call before that update (another frame, init, a target added, reset or removed, close) first
has them put back and drops the speculative answers, errors included, so every call pattern
gives the results of a tracker that never speculated, bit for bit. In-process trackers never
speculate (their work would only move, not overlap).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from autotrack.errors import InputError
from autotrack.params import TrackerParams
from autotrack.result import TrackResult
from autotrack.tracker.parallel.speculation import Speculation
from autotrack.tracker.parallel.target_process import SharedFrame, TargetProcess, WorkerPool
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
        processes: int = 1,
        worker_pool: WorkerPool | None = None,
        new_tracker: Callable[[], AutoTrack] | None = None,
    ) -> None:
        """`target_ids` fixes the targets `init` expects (empty: whatever `init` is given);
        `threads` > 1 runs this process's targets concurrently; `processes` > 1 spreads the
        targets over this process and up to `processes - 1` child processes, each taken from
        `worker_pool` (None: a pool of this tracker's own, closed with it) when a target is
        first given to it. `new_tracker` makes each target's tracker instead of an AutoTrack
        of `params` (any tracker with its call shape: `autotrack.hybrid.factory`); the child
        processes run AutoTrack only, so it needs `processes` 1."""
        if threads < 1:
            raise InputError(f"threads must be at least 1, got {threads}")
        if processes < 1:
            raise InputError(f"processes must be at least 1, got {processes}")
        if processes > 1 and os.name != "posix":
            raise InputError("tracking in several processes needs a POSIX system (Linux, macOS)")
        if new_tracker is not None and processes > 1:
            raise InputError("child processes track with AutoTrack only: use threads")
        self.params = params
        self._make_tracker = new_tracker
        self.colour_table = colour_table
        self.threads = threads
        self.processes = processes
        self._expected = tuple(target_ids)
        self._trackers: dict[str, AutoTrack] = {}  # this process's targets
        self._owners: dict[str, int] = {}  # every target: 0 here, i > 0 the i-th child
        self._frame_index = -1
        self._pool = ThreadPoolExecutor(max_workers=threads) if threads > 1 else None
        self._own_pool = worker_pool is None and processes > 1
        self._worker_pool = WorkerPool() if self._own_pool else worker_pool
        self._children: list[TargetProcess | None] = [None] * (processes - 1)
        self._shared_frame = SharedFrame() if self._children else None
        self._speculation: Speculation | None = None

    @property
    def target_ids(self) -> tuple[str, ...]:
        """Targets currently tracked, in the order they were added."""
        return tuple(self._owners)

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
        self._cancel_speculation()
        frame = _shared_frame(frame)
        for target_id in list(self._owners):
            self._drop(target_id)
        starts = {str(k): tuple(b) for k, b in boxes.items()}
        for target_id in starts:
            self._owners[target_id] = self._least_loaded_owner()
        self._trackers = {k: self._new_tracker() for k, o in self._owners.items() if o == 0}
        self._frame_index = 0
        handle = self._publish(frame)
        for target_id, box in starts.items():
            if self._owners[target_id] > 0:
                self._child(self._owners[target_id]).start(target_id, handle, box)
        return self._run(lambda target_id, tracker: tracker.init(frame, starts[target_id]))

    def update(
        self, frame: np.ndarray, next_frame: Callable[[], np.ndarray] | None = None
    ) -> dict[str, TrackResult]:
        """Track every target into the next frame. `next_frame` gives the frame the update
        after this one will be given: it is called before this process's targets are tracked,
        and the children go on to that frame (`speculate`) as soon as they have tracked this
        one (an error in it, or an invalid frame: no speculation)."""
        if self._speculation is not None and self._speculation.matches(frame):
            # The children have been tracking this frame since `speculate`.
            self._speculation = None
            frame = _shared_frame(frame)
            self._frame_index += 1
            return self._run(lambda _target_id, tracker: tracker.update(frame), next_frame)
        self._cancel_speculation()
        if self._frame_index < 0:
            raise InputError("call init(frame, boxes) before update(frame)")
        frame = _shared_frame(frame)
        self._frame_index += 1
        handle = self._publish(frame)
        for index, child in enumerate(self._children, start=1):
            target_ids = [k for k, owner in self._owners.items() if owner == index]
            if target_ids and child is not None:
                child.update(target_ids, handle)
        return self._run(lambda _target_id, tracker: tracker.update(frame), next_frame)

    def speculate(self, next_frame: np.ndarray) -> bool:
        """Start the children's targets on `next_frame`, the frame the next `update` will be
        given (the same read-only array, or one of equal values): they track it while the
        caller goes on. Any other call first undoes it. Whether it started (only with a child
        tracking a target, after `init`, and for a valid frame; an invalid one is reported by
        `update`)."""
        self._cancel_speculation()
        if self._frame_index < 0 or any(c is not None and c.pending for c in self._children):
            return False
        return self._speculate(next_frame)

    def add_target(self, target_id: str, frame: np.ndarray, box: Box) -> TrackResult:
        """Start a new target on `frame`, which must be the frame last processed."""
        self._cancel_speculation()
        if target_id in self._owners:
            raise InputError(f"target {target_id!r} already exists; use reset_target to move it")
        return self._start(target_id, frame, box)

    def remove_target(self, target_id: str) -> None:
        """Stop tracking a target."""
        self._cancel_speculation()
        if target_id not in self._owners:
            raise InputError(f"no target {target_id!r} (targets: {', '.join(self._owners)})")
        self._drop(target_id)

    def reset_target(self, target_id: str, frame: np.ndarray, box: Box) -> TrackResult:
        """Restart a target from a corrected box on `frame` (the frame last processed), e.g. when
        a user fixes a drifting box; the other targets are untouched."""
        self._cancel_speculation()
        if target_id not in self._owners:
            raise InputError(f"no target {target_id!r} (targets: {', '.join(self._owners)})")
        return self._start(target_id, frame, box)

    def close(self) -> None:
        """Stop the worker threads and child processes (this process's trackers stay readable)."""
        self._cancel_speculation()
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        for child in self._children:
            if child is not None and self._worker_pool is not None:
                self._worker_pool.release(child)
        self._children = []
        if self._shared_frame is not None:
            self._shared_frame.close()
            self._shared_frame = None
        if self._own_pool and self._worker_pool is not None:
            self._worker_pool.close()

    def __enter__(self) -> MultiTracker:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- internals --------------------------------------------------------------------------

    def _new_tracker(self) -> AutoTrack:
        if self._make_tracker is not None:
            return self._make_tracker()
        return AutoTrack(self.params, colour_table=self.colour_table)

    def _start(self, target_id: str, frame: np.ndarray, box: Box) -> TrackResult:
        if self._frame_index < 0:
            raise InputError("call init(frame, boxes) before adding or resetting a target")
        frame = _shared_frame(frame)
        owner = self._owners.get(target_id)
        if owner is None:
            owner = self._least_loaded_owner()
        if owner == 0:
            tracker = self._new_tracker()
            result = tracker.init(frame, tuple(box))
            self._trackers[target_id] = tracker
        else:
            child = self._child(owner)
            child.start(target_id, self._publish(frame, always=True), tuple(box))
            result = _answers(child)[target_id]
        self._owners[target_id] = owner
        return result.renumbered(self._frame_index)

    def _drop(self, target_id: str) -> None:
        owner = self._owners.pop(target_id)
        if owner == 0:
            del self._trackers[target_id]
        else:
            self._child(owner).remove(target_id)
            _answers(self._child(owner))

    def _speculate(self, next_frame: np.ndarray) -> bool:
        """Send each child tracking targets a speculative update into `next_frame` (see
        `speculate`). Only when every command a child has not answered reads the frame written
        last: `SharedFrame` writes this one into its other segment."""
        owners = sorted({owner for owner in self._owners.values() if owner > 0})
        if not owners or self._shared_frame is None:
            return False
        try:
            frame = _shared_frame(next_frame)
        except InputError:
            return False
        handle = self._shared_frame.write(frame)
        sent: list[int] = []
        try:
            for owner in owners:
                target_ids = [k for k, o in self._owners.items() if o == owner]
                self._child(owner).update(target_ids, handle, speculative=True)
                sent.append(owner)
        finally:
            if sent:  # what was sent is undone or consumed like any speculation
                seen = self._shared_frame.view(handle)
                self._speculation = Speculation(next_frame, seen, tuple(sent))
        return sent == owners

    def _cancel_speculation(self) -> None:
        """Undo an outstanding speculation: each child puts its trackers back as they were
        before it; its answers (results or errors) and the rollback's are dropped."""
        speculation, self._speculation = self._speculation, None
        if speculation is None:
            return
        children = [self._children[owner - 1] for owner in speculation.owners]
        for child in children:
            with contextlib.suppress(Exception):  # a child gone is reported by the next command
                child.rollback()
        for child in children:
            while child.pending:
                with contextlib.suppress(Exception):
                    child.collect()

    def _least_loaded_owner(self) -> int:
        """This process (0) or the child (1, 2, ...) with the fewest targets, first on ties."""
        counts = [0] * self.processes
        for owner in self._owners.values():
            counts[owner] += 1
        return counts.index(min(counts))

    def _child(self, owner: int) -> TargetProcess:
        """The child process `owner` (1, 2, ...), taken from the pool on first use."""
        child = self._children[owner - 1]
        if child is None:
            if self._worker_pool is None:
                raise InputError("this tracker is closed")
            child = self._worker_pool.acquire(self.params, self.colour_table)
            self._children[owner - 1] = child
        return child

    def _publish(self, frame: np.ndarray, *, always: bool = False) -> tuple | None:
        """The frame in shared memory for the children (None without children, or when no
        child tracks a target and not `always`)."""
        if self._shared_frame is None:
            return None
        if not always and not any(owner > 0 for owner in self._owners.values()):
            return None
        return self._shared_frame.write(frame)

    def _run(
        self,
        step: Callable[[str, AutoTrack], TrackResult],
        next_frame: Callable[[], np.ndarray] | None = None,
    ) -> dict[str, TrackResult]:
        """Speculate on `next_frame()` when given (first: the children queue it behind this
        frame, and never wait while this process tracks), apply `step` to every (target id,
        tracker) of this process, concurrently when there is a pool, then collect the
        children's answers to the command sent to them before (the speculation's are left for
        the next update)."""
        items = list(self._trackers.items())
        try:
            if next_frame is not None:
                self._speculate_on(next_frame)
            if self._pool is None or len(items) < 2:
                results = {k: step(k, tracker) for k, tracker in items}
            else:
                futures = {k: self._pool.submit(step, k, tracker) for k, tracker in items}
                results = {k: future.result() for k, future in futures.items()}
        finally:
            results_of_children = self._collect_children()
        results.update(results_of_children)
        index = self._frame_index
        return {k: results[k].renumbered(index) for k in self._owners if k in results}

    def _speculate_on(self, next_frame: Callable[[], np.ndarray]) -> None:
        """`_speculate` on the frame `next_frame()` gives, when it gives one (not asked for
        without a child tracking a target: nothing to speculate)."""
        if not any(owner > 0 for owner in self._owners.values()):
            return
        try:
            frame = next_frame()
        except Exception:  # noqa: BLE001 - the frame's own error comes when it is tracked
            return
        self._speculate(frame)

    def _collect_children(self) -> dict[str, TrackResult]:
        """Every pending answer of every child but a speculation's; the first error is raised
        once all are in."""
        results: dict[str, TrackResult] = {}
        error: Exception | None = None
        speculating = () if self._speculation is None else self._speculation.owners
        for owner, child in enumerate(self._children, start=1):
            while child is not None and child.pending > (owner in speculating):
                try:
                    results.update(child.collect())
                except Exception as failure:
                    error = error or failure
        if error is not None:
            raise error
        return results


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the system tells it)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def default_concurrency(target_count: int) -> tuple[int, int]:
    """(threads, processes) for `target_count` targets, as `autotrack localize` and the app
    choose them: with two targets or more, two cores or more and a POSIX system, one thread and
    two processes (half the targets in a child: parallel where threads share the GIL, and the
    results are those of one process bit for bit); else two threads for several targets
    (measured in docs/benchmarks.md, Speed) and one for a single target."""
    if target_count >= 2 and available_cores() >= 2 and os.name == "posix":
        return 1, 2
    return (2 if target_count >= 2 else 1), 1


def chosen_concurrency(
    threads: int | None, processes: int | None, target_count: int
) -> tuple[int, int]:
    """(threads, processes) from a caller's choice, None where it made none: both None,
    `default_concurrency`; threads alone, all the targets in this process; processes alone, one
    thread per process when several, else two."""
    if threads is None and processes is None:
        return default_concurrency(target_count)
    if processes is None:
        return int(threads or 1), 1
    if threads is None:
        return (1 if processes > 1 else 2), processes
    return threads, processes


def _answers(child: TargetProcess) -> dict[str, TrackResult]:
    """Every answer `child` owes (a child just taken from its pool owes one for its settings)."""
    results: dict[str, TrackResult] = {}
    while child.pending:
        results.update(child.collect())
    return results


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
