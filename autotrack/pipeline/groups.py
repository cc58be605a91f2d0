"""Trackers grouped by the frame they are at: one MultiTracker per group.

A group's targets all sit at the same last tracked frame (its head). Boxes drawn on the same
frame join one group, so the usual case (every box on the first frame, then play) is a single
MultiTracker. A box redrawn on a target whose group is at that frame resets the target in
place; redrawn at an earlier frame, the target leaves its group and restarts in the group at
that frame (or a new one), and the other targets keep their filters.

NanoTrack and the hybrid (`autotrack.hybrid.factory`) run in this process only: the child
processes track with AutoTrack, so for them the processes asked for become threads.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from autotrack.hybrid.factory import SIAMESE_TRACKERS, make_tracker
from autotrack.io.frames import FrameSource
from autotrack.params import TrackerParams
from autotrack.result import TrackResult
from autotrack.tracker.parallel.multi import MultiTracker
from autotrack.tracker.parallel.target_process import WorkerPool

Box = tuple[float, float, float, float]


def following_frame(frames: FrameSource, frame_index: int, horizon: int | None) -> int | None:
    """The frame a pipeline advancing frame by frame up to `horizon` tracks after
    `frame_index`: None without a horizon, past it or the sequence's end, or when the source
    does not track that frame right after this one (a live source skips the frames it drops;
    a live run advances without a horizon)."""
    following = frame_index + 1
    if (
        horizon is None
        or following > horizon
        or following >= len(frames)
        or frames.previous_index(following) != frame_index
    ):
        return None
    return following


@dataclass
class _Group:
    tracker: MultiTracker
    head: int
    target_ids: list[str]


class TrackerGroups:
    """The MultiTrackers of one pipeline; results carry the sequence's frame index."""

    def __init__(
        self,
        params: TrackerParams,
        threads: int,
        processes: int = 1,
        worker_pool: WorkerPool | None = None,
        tracker_name: str | None = None,
    ) -> None:
        """`worker_pool` lends the MultiTrackers their child processes (None with `processes`
        > 1: a pool of the groups' own, closed with them). `tracker_name` `nanotrack` or
        `hybrid` tracks with them (`params`: the hybrid's filter's), in `max(threads,
        processes)` threads; else AutoTrack of `params`."""
        self.params = params
        self.new_tracker = None
        if tracker_name in SIAMESE_TRACKERS:
            self.new_tracker = lambda: make_tracker(tracker_name, params)
            threads, processes = max(threads, processes), 1
        self.threads = threads
        self.processes = processes
        self._own_pool = worker_pool is None and processes > 1
        self._worker_pool = WorkerPool() if self._own_pool else worker_pool
        self._groups: list[_Group] = []

    @property
    def tracked_until(self) -> int:
        """Last frame every group has reached (-1 without groups)."""
        return min((group.head for group in self._groups), default=-1)

    def __bool__(self) -> bool:
        return bool(self._groups)

    def start(
        self, frame_index: int, frame: np.ndarray, boxes: Mapping[str, Box]
    ) -> dict[str, TrackResult]:
        """(Re)start each target of `boxes` on `frame` (sequence frame `frame_index`)."""
        results: dict[str, TrackResult] = {}
        fresh: dict[str, Box] = {}
        for target_id, box in boxes.items():
            current = self._group_of(target_id)
            joined = next((g for g in self._groups if g.head == frame_index), None)
            if current is not None and current.head == frame_index:
                results[target_id] = current.tracker.reset_target(target_id, frame, box)
            elif joined is not None:
                results[target_id] = joined.tracker.add_target(target_id, frame, box)
                joined.target_ids.append(target_id)
                if current is not None:
                    self._leave(target_id, current)
            else:
                fresh[target_id] = box
        if fresh:
            tracker = MultiTracker(
                self.params,
                list(fresh),
                threads=self.threads,
                processes=self.processes,
                worker_pool=self._worker_pool,
                new_tracker=self.new_tracker,
            )
            try:
                results.update(tracker.init(frame, fresh))
            except Exception:
                tracker.close()
                raise
            for target_id in fresh:
                current = self._group_of(target_id)
                if current is not None:
                    self._leave(target_id, current)
            self._groups.append(_Group(tracker, frame_index, list(fresh)))
        return {k: results[k].renumbered(frame_index) for k in boxes}

    def advance(
        self,
        frame_index: int,
        frames: FrameSource,
        frame_of: Callable[[int], np.ndarray],
        horizon: int | None = None,
    ) -> tuple[dict[str, TrackResult], float]:
        """Track every group whose head is the frame before `frame_index` in `frames` (its
        `previous_index`, usually `frame_index - 1`) onto `frame_index`.

        `frame_of(index)` gives the frame (read only when a group is due). `horizon`: the
        caller advances frame by frame up to it next; the groups' child processes then go on
        to the next frame as soon as they have tracked this one (`following_frame`,
        `MultiTracker.update`'s `next_frame`; a frame that cannot be read then is not
        speculated on, its error comes when it is tracked). Returns the results and the
        tracking time in seconds (NaN when no group was due).
        """
        previous = frames.previous_index(frame_index)
        due = [group for group in self._groups if group.head == previous]
        if not due:
            return {}, float("nan")
        frame = frame_of(frame_index)
        started = time.perf_counter()
        results: dict[str, TrackResult] = {}
        following = following_frame(frames, frame_index, horizon)
        next_frame = None if following is None else lambda: frame_of(following)
        for group in due:
            for target_id, result in group.tracker.update(frame, next_frame).items():
                results[target_id] = result.renumbered(frame_index)
            group.head = frame_index
        return results, time.perf_counter() - started

    def remove(self, target_id: str) -> None:
        """Stop tracking a target (nothing when it is not tracked)."""
        group = self._group_of(target_id)
        if group is not None:
            self._leave(target_id, group)

    def close(self) -> None:
        """Stop every tracker's threads and child processes."""
        for group in self._groups:
            group.tracker.close()
        self._groups.clear()
        if self._own_pool and self._worker_pool is not None:
            self._worker_pool.close()

    def _group_of(self, target_id: str) -> _Group | None:
        return next((group for group in self._groups if target_id in group.target_ids), None)

    def _leave(self, target_id: str, group: _Group) -> None:
        group.target_ids.remove(target_id)
        if group.target_ids:
            group.tracker.remove_target(target_id)
        else:
            group.tracker.close()
            self._groups.remove(group)
