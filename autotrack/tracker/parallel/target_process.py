"""Targets tracked in a child process, so that several targets run on several cores.

Threads cannot do this well: a target's update is hundreds of short steps, and the Python and
small-array numpy work between the compiled kernels and the FFTs holds the GIL, so two threads
serialise on it (see docs/benchmarks.md, Speed). A `TargetProcess` owns its own `AutoTrack`s in
a child process. The parent writes each frame once into shared memory (`SharedFrame`, read by
every child), sends a short command over a socket and later collects the `TrackResult`s (a
box, signals and three small maps each). The child runs the same code on the same inputs, so
its results are bit for bit those of an in-process tracker.

The frames alternate between two segments, so the parent can write the next frame while a
child still reads the current one. A speculative update (`update(..., speculative=True)`, sent
before the parent knows the frame is wanted: `MultiTracker.speculate`) first copies the
trackers it moves (~0.1 ms each; the copy shares their FFT plans, which hold scratch buffers
only, and their frozen parameters); `rollback` puts those copies back, so a tracker rolled
back continues exactly as if the update had never run.

A child is a fresh interpreter (`python -c ...`, talking over a socket pair), neither a fork
(which would copy the parent's threads' locks: the app runs a web server) nor a
`multiprocessing` spawn (which re-runs the caller's main script, unguarded in most scripts).
It imports the tracker and loads the cached numba kernels once (~1 s on an idle machine, in
the background while the parent goes on) and uses as many OpenCV threads as the parent. A
`WorkerPool` lends children to MultiTrackers: a closed MultiTracker gives its children back and
the next one of the same pool starts at once, with no start-up to pay again.
"""

from __future__ import annotations

import contextlib
import copy
import os
import socket
import subprocess
import sys
import threading
import traceback
from collections.abc import Mapping, Sequence
from multiprocessing import resource_tracker
from multiprocessing.connection import Connection
from multiprocessing.shared_memory import SharedMemory

import numpy as np

from autotrack.params import TrackerParams
from autotrack.result import TrackResult

Box = Sequence[float]
FrameHandle = tuple[str, tuple[int, ...]]
"""A frame in shared memory: the segment's name and the frame's shape (uint8)."""


class WorkerError(RuntimeError):
    """A tracking child process stopped or failed in a way that is not the caller's input."""


class SharedFrame:
    """Two shared-memory segments, written in turn, holding the frames for every child to read:
    the next frame can be written while the children still read the one written before it."""

    def __init__(self) -> None:
        self._memory: list[SharedMemory | None] = [None, None]
        self._last = 1  # the segment written last

    def write(self, frame: np.ndarray) -> FrameHandle:
        """Copy `frame` (uint8, contiguous) into the segment not written last; returns its
        handle. The caller makes sure no child still reads that segment's frame (every command
        but those given the last handle answered)."""
        slot = self._last = 1 - self._last
        memory = self._memory[slot]
        if memory is None or memory.size < frame.nbytes:
            _remove(memory)
            memory = self._memory[slot] = SharedMemory(create=True, size=max(frame.nbytes, 1))
        view = np.ndarray(frame.shape, np.uint8, buffer=memory.buf)
        view[...] = frame
        return memory.name, frame.shape

    def view(self, handle: FrameHandle) -> np.ndarray:
        """A read-only view of the frame `handle` names, as the children read it (valid until
        its segment is written again)."""
        name, shape = handle
        memory = next(m for m in self._memory if m is not None and m.name == name)
        frame = np.ndarray(shape, np.uint8, buffer=memory.buf)
        frame.flags.writeable = False
        return frame

    def close(self) -> None:
        """Release and remove the segments."""
        for memory in self._memory:
            _remove(memory)
        self._memory = [None, None]


def _remove(memory: SharedMemory | None) -> None:
    if memory is not None:
        memory.close()
        memory.unlink()


class TargetProcess:
    """A child process tracking some of the targets; commands are answered in order."""

    def __init__(self) -> None:
        parent_end, child_end = socket.socketpair()
        self._process = subprocess.Popen(
            [sys.executable, "-c", _CHILD_MAIN, str(child_end.fileno())],
            pass_fds=[child_end.fileno()],
            stdin=subprocess.DEVNULL,
            env=dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p)),
        )
        child_end.close()
        self._connection = Connection(parent_end.detach())
        self._pending = 0

    @property
    def pid(self) -> int:
        """The child's process id."""
        return self._process.pid

    def alive(self) -> bool:
        """Whether the child is still running."""
        return self._process.poll() is None

    def configure(self, params: TrackerParams, colour_table: np.ndarray | None) -> None:
        """Drop every tracker and take these settings (and this process's OpenCV threads)."""
        import cv2

        self._send(("configure", params, colour_table, cv2.getNumThreads()))

    def start(self, target_id: str, frame: FrameHandle, box: Box) -> None:
        """Ask for a new tracker (or a restarted one) for `target_id` on `frame`."""
        self._send(("start", target_id, frame, tuple(float(v) for v in box)))

    def update(
        self, target_ids: Sequence[str], frame: FrameHandle, *, speculative: bool = False
    ) -> None:
        """Ask for these targets to be tracked into `frame`; `speculative`: keep a copy of
        their trackers first, for `rollback` to restore."""
        self._send(("update", tuple(target_ids), frame, speculative))

    def rollback(self) -> None:
        """Put the trackers of the last speculative update back as they were before it."""
        self._send(("rollback",))

    def remove(self, target_id: str) -> None:
        """Drop a target's tracker."""
        self._send(("remove", target_id))

    @property
    def pending(self) -> int:
        """Commands sent whose answers are not collected yet."""
        return self._pending

    def collect(self) -> dict[str, TrackResult]:
        """The answer to the oldest command not yet collected (re-raises the child's error)."""
        self._pending -= 1
        try:
            status, payload = self._connection.recv()
        except (EOFError, OSError) as error:
            raise WorkerError(
                f"the tracking process {self._process.pid} stopped unexpectedly "
                f"(exit code {self._process.poll()})"
            ) from error
        if status == "error":
            raise payload
        return payload

    def close(self) -> None:
        """Stop the child (answers still pending are dropped)."""
        with contextlib.suppress(OSError):  # the child may be gone already
            self._connection.send(("stop",))
        try:
            self._process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait()
        self._connection.close()

    def _send(self, command: tuple) -> None:
        try:
            self._connection.send(command)
        except (BrokenPipeError, OSError) as error:
            raise WorkerError(f"the tracking process {self._process.pid} has stopped") from error
        self._pending += 1


_CHILD_MAIN = "import sys; from autotrack.tracker.parallel.target_process import serve; serve(int(sys.argv[1]))"


def serve(descriptor: int) -> None:
    """The child's loop on the socket `descriptor`: one answer per command until "stop" or the
    parent goes away."""
    connection = Connection(descriptor)
    state = _ChildState()
    try:
        while True:
            try:
                command = connection.recv()
            except (EOFError, OSError):
                return
            if command[0] == "stop":
                return
            try:
                connection.send(("ok", state.answer(command)))
            except Exception as error:  # sent back to the parent, which re-raises it
                connection.send(("error", _picklable(error)))
    finally:
        state.frames.close()
        connection.close()


class _ChildState:
    """What a child holds: its settings, its targets' trackers, its view of the frames."""

    def __init__(self) -> None:
        self.params: TrackerParams | None = None
        self.colour_table: np.ndarray | None = None
        self.trackers: dict = {}
        self.snapshots: dict = {}  # target id -> its tracker before the last speculative update
        self.frames = _AttachedFrames()

    def answer(self, command: tuple) -> Mapping[str, TrackResult]:
        from autotrack.tracker.tracker import AutoTrack

        kind = command[0]
        if kind == "configure":
            import cv2

            _, self.params, self.colour_table, opencv_threads = command
            cv2.setNumThreads(opencv_threads)
            self.trackers, self.snapshots = {}, {}
            return {}
        if kind == "start":
            _, target_id, handle, box = command
            self.snapshots.pop(target_id, None)
            tracker = AutoTrack(self.params, colour_table=self.colour_table)
            result = tracker.init(self.frames.view(handle), box)
            self.trackers[target_id] = tracker
            return {target_id: result}
        if kind == "update":
            _, target_ids, handle, speculative = command
            self._keep_snapshots(target_ids, speculative)
            frame = self.frames.view(handle)
            return {target_id: self.trackers[target_id].update(frame) for target_id in target_ids}
        if kind == "rollback":
            self.trackers.update(self.snapshots)
            self.snapshots = {}
            return {}
        if kind == "remove":
            self.trackers.pop(command[1], None)
            self.snapshots.pop(command[1], None)
            return {}
        raise ValueError(f"unknown command {kind!r}")

    def _keep_snapshots(self, target_ids: Sequence[str], speculative: bool) -> None:
        """Before a speculative update, a copy of each of its trackers (only the last
        speculative update's are kept); before a plain one, drop the copies of its targets.

        The copy shares the tracker's backend (`backend`: its buffers are scratch memory only,
        every one written before it is read) and its parameters (frozen); a tracker put back continues exactly as if the update had never
        run."""
        if not speculative:
            for target_id in target_ids:
                self.snapshots.pop(target_id, None)
            return
        self.snapshots = {}
        for target_id in target_ids:
            tracker = self.trackers[target_id]
            shared = {id(tracker.backend): tracker.backend, id(tracker.params): tracker.params}
            self.snapshots[target_id] = copy.deepcopy(tracker, shared)


class _AttachedFrames:
    """The child's read-only views of the parent's shared frame segments (the two a
    `SharedFrame` writes in turn stay attached)."""

    KEPT = 2

    def __init__(self) -> None:
        self._memory: dict[str, SharedMemory] = {}

    def view(self, handle: FrameHandle) -> np.ndarray:
        name, shape = handle
        memory = self._memory.pop(name, None)  # put back last: the least recent goes first
        if memory is None:
            while len(self._memory) >= self.KEPT:  # a segment the parent replaced
                self._memory.pop(next(iter(self._memory))).close()
            memory = SharedMemory(name=name)
            # The parent owns (and removes) the segment: without this the child's own resource
            # tracker would remove it when the child exits, and warn about a leak.
            resource_tracker.unregister("/" + memory.name, "shared_memory")  # POSIX name
        self._memory[name] = memory
        frame = np.ndarray(shape, np.uint8, buffer=memory.buf)
        frame.flags.writeable = False
        return frame

    def close(self) -> None:
        for memory in self._memory.values():
            memory.close()
        self._memory = {}


def _picklable(error: Exception) -> Exception:
    """The error itself when it survives pickling, else a WorkerError with its traceback."""
    import pickle

    try:
        pickle.loads(pickle.dumps(error))
        return error
    except Exception:
        return WorkerError("".join(traceback.format_exception(error)))


IDLE_LIMIT = 4
"""Idle children a `WorkerPool` keeps for the next MultiTracker (a child's start-up is paid
once)."""


class WorkerPool:
    """Child processes lent to MultiTrackers: a closed MultiTracker gives its children back,
    the next one takes them already started (imports done, kernels loaded).

    One pool per owner that runs MultiTrackers one after another or side by side (a pipeline,
    the app's server, a benchmark); `close` stops the idle children, and a child still lent
    out stops when it is given back to a closed pool.
    """

    def __init__(self, idle_limit: int = IDLE_LIMIT) -> None:
        self.idle_limit = idle_limit
        self._idle: list[TargetProcess] = []
        self._lock = threading.Lock()
        self._closed = False

    def acquire(self, params: TrackerParams, colour_table: np.ndarray | None) -> TargetProcess:
        """An idle child if there is one, else a new one, set to track with `params`."""
        with self._lock:
            while self._idle:
                child = self._idle.pop()
                if child.alive():
                    break
                child.close()
            else:
                child = TargetProcess()
        child.configure(params, colour_table)
        return child

    def release(self, child: TargetProcess) -> None:
        """Give a child back: its trackers are dropped and it waits for the next MultiTracker
        (or it is stopped, when it failed, the pool is closed or enough children wait)."""
        try:
            while child.pending:
                child.collect()
            child.configure(TrackerParams(), None)  # drops the trackers
            child.collect()
        except Exception:
            child.close()
            return
        with self._lock:
            if not self._closed and len(self._idle) < self.idle_limit:
                self._idle.append(child)
                return
        child.close()

    @property
    def idle(self) -> int:
        """Children waiting to be lent."""
        with self._lock:
            return len(self._idle)

    def close(self) -> None:
        """Stop every idle child; children given back later are stopped too."""
        with self._lock:
            children = list(self._idle)
            self._idle.clear()
            self._closed = True
        for child in children:
            child.close()

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
