"""Resumable runs of (label, sequence) pairs, shared by the benchmark and the sweep.

A label names what tracks: a tracker (`autotrack.evaluation.benchmark`) or a parameter
combination (`autotrack.evaluation.sweep`). Each pair's result is saved as it arrives:

- ``DIR/<label>/<sequence>.txt``: one x,y,w,h row per frame, 1-based (benchmark convention),
  the file other toolkits read;
- ``DIR/<label>/<sequence>.time.json``: per-frame tracking times and the colour feature. A pair
  is resumed (not rerun) when both files exist, the box file has one row per frame and the colour
  feature matches.

The work is a picklable function of one pair returning a `TaskResult`, run inline (jobs=1), in a
local pool of single-thread processes (jobs > 1) or on any `concurrent.futures.Executor` passed
in (a Dask cluster's). Timing is the wall time of the tracker's init/update calls only (not frame
decoding), with OpenCV, numba and BLAS limited to one thread.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from autotrack.errors import InputError
from autotrack.evaluation.datasets import Sequence as BenchmarkSequence
from autotrack.evaluation.peers import BoxTracker
from autotrack.io import otb_boxes
from autotrack.io.atomic import write_text

SINGLE_THREAD_ENVIRONMENT: dict[str, str] = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}
"""Environment of worker processes: BLAS, OpenMP and numba read it when they load."""


@dataclass(frozen=True, eq=False)
class TaskResult:
    """Boxes and per-frame tracking times of one tracker on one sequence."""

    tracker: str
    """Tracker name (or a sweep combination's label)."""
    sequence: str
    """Sequence name."""
    boxes: np.ndarray
    """(N, 4) float64 boxes x, y, w, h, 0-based pixels."""
    times: np.ndarray
    """(N,) seconds spent in the tracker's init (frame 0) and update calls."""

    @property
    def frames(self) -> int:
        """Number of frames tracked."""
        return len(self.boxes)

    @property
    def seconds(self) -> float:
        """Total tracking time in seconds."""
        return float(np.sum(self.times))

    @property
    def fps(self) -> float:
        """Frames per second of tracking time."""
        return self.frames / self.seconds if self.seconds > 0 else math.inf


@contextmanager
def single_thread() -> Iterator[None]:
    """Limit OpenCV, numba and (when threadpoolctl is installed) BLAS to one thread, then restore."""
    previous_cv_threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        import numba

        previous_numba_threads = numba.get_num_threads()
        numba.set_num_threads(1)
    except ImportError:
        numba, previous_numba_threads = None, 0
    try:
        from threadpoolctl import threadpool_limits

        blas_limits = threadpool_limits(limits=1)
    except ImportError:
        blas_limits = nullcontext()
    try:
        with blas_limits:
            yield
    finally:
        cv2.setNumThreads(previous_cv_threads)
        if numba is not None:
            numba.set_num_threads(previous_numba_threads)


@contextmanager
def environment(variables: Mapping[str, str]) -> Iterator[None]:
    """Set environment variables (inherited by processes started inside), then restore them."""
    previous = {name: os.environ.get(name) for name in variables}
    os.environ.update(variables)
    try:
        yield
    finally:
        for name, value in previous.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def track_timed(
    label: str, new_tracker: Callable[[], BoxTracker], sequence: BenchmarkSequence
) -> TaskResult:
    """Track one sequence from its first ground-truth box with a tracker made (and run) on one
    thread, timing only the tracker's init/update calls."""
    count = len(sequence)
    boxes = np.empty((count, 4), dtype=np.float64)
    times = np.empty(count, dtype=np.float64)
    init_box = sequence.init_box
    with sequence.frames() as frames, single_thread():
        tracker = new_tracker()
        for index in range(count):
            frame = frames.read(index)
            start = time.perf_counter()
            box = tracker.init(frame, init_box) if index == 0 else tracker.update(frame)
            times[index] = time.perf_counter() - start
            boxes[index] = box
    return TaskResult(label, sequence.name, boxes, times)


def result_paths(out_dir: Path, label: str, sequence: str) -> tuple[Path, Path]:
    """The box file and the timing file of one (label, sequence) pair."""
    folder = Path(out_dir) / label
    return folder / f"{sequence}.txt", folder / f"{sequence}.time.json"


def save_result(out_dir: Path, result: TaskResult, colour_feature: str | None) -> None:
    """Write the box file, then the timing file (its presence marks the pair as done)."""
    boxes_path, timing_path = result_paths(out_dir, result.tracker, result.sequence)
    boxes_path.parent.mkdir(parents=True, exist_ok=True)
    otb_boxes.write_boxes(boxes_path, result.boxes)  # each file whole or not at all
    timing = {
        "tracker": result.tracker,
        "sequence": result.sequence,
        "frames": result.frames,
        "colour_feature": colour_feature,
        "seconds": result.seconds,
        "times": [float(t) for t in result.times],
    }
    write_text(timing_path, json.dumps(timing) + "\n")


def load_result(
    out_dir: Path, label: str, sequence: BenchmarkSequence, colour_feature: str | None
) -> TaskResult | None:
    """A saved result for the pair, or None when it is missing, incomplete or from another
    colour feature (then the pair is rerun)."""
    boxes_path, timing_path = result_paths(out_dir, label, sequence.name)
    if not (boxes_path.is_file() and timing_path.is_file()):
        return None
    try:
        timing = json.loads(timing_path.read_text())
        boxes = otb_boxes.read_boxes(boxes_path)
        times = np.asarray(timing["times"], dtype=np.float64)
    except (InputError, ValueError, KeyError, TypeError):
        return None
    complete = len(boxes) == len(sequence) == len(times) == timing.get("frames")
    if not complete or timing.get("colour_feature") != colour_feature:
        return None
    return TaskResult(label, sequence.name, boxes, times)


@dataclass(frozen=True, eq=False)
class ResumableRuns:
    """Every pair's result, saved earlier or computed now."""

    results: dict[tuple[str, str], TaskResult]
    """(label, sequence name) -> result."""
    computed: int
    """Pairs run now."""
    resumed: int
    """Pairs read back from their saved files."""


def run_resumable(
    labels: Sequence[str],
    sequences: Sequence[BenchmarkSequence],
    out_dir: Path,
    colour_features: Mapping[str, str | None],
    work: Callable[[str, BenchmarkSequence], tuple[Callable[..., TaskResult], tuple]],
    *,
    jobs: int = 1,
    executor: Executor | None = None,
    progress: bool = True,
    description: str = "runs",
) -> ResumableRuns:
    """Run every (label, sequence) pair not already saved under `out_dir`, saving each result
    as it arrives. `work(label, sequence)` gives the picklable function and its arguments."""
    results: dict[tuple[str, str], TaskResult] = {}
    pending: list[tuple[Callable[..., TaskResult], tuple]] = []
    lengths: list[int] = []
    for label in labels:
        for sequence in sequences:
            saved = load_result(out_dir, label, sequence, colour_features[label])
            if saved is None:
                pending.append(work(label, sequence))
                lengths.append(len(sequence))
            else:
                results[(label, sequence.name)] = saved
    resumed = len(results)
    # Longest sequences first so parallel workers finish together.
    order = sorted(range(len(pending)), key=lambda index: -lengths[index])
    pending = [pending[index] for index in order]
    with tqdm(total=len(pending), desc=description, unit="run", disable=not progress) as bar:
        for result in _execute(pending, jobs, executor):
            save_result(out_dir, result, colour_features[result.tracker])
            results[(result.tracker, result.sequence)] = result
            bar.set_postfix_str(f"{result.tracker} {result.sequence} {result.fps:.1f} fps")
            bar.update()
    return ResumableRuns(results, computed=len(pending), resumed=resumed)


def _execute(
    tasks: list[tuple[Callable[..., TaskResult], tuple]], jobs: int, executor: Executor | None
) -> Iterator[TaskResult]:
    if not tasks:
        return
    if executor is None and jobs == 1:
        for function, arguments in tasks:
            yield function(*arguments)
        return
    if executor is not None:
        yield from _unordered(_submit_all(executor, tasks))
        return
    with ProcessPoolExecutor(
        max_workers=min(jobs, len(tasks)), mp_context=get_context("spawn")
    ) as pool:
        # The pool starts its workers as the tasks are submitted: only they get the
        # single-thread environment. Outside this window this process's own numba keeps the
        # thread count it started with (numba refuses a changed NUMBA_NUM_THREADS once its
        # threads run), whatever the caller does between results.
        with environment(SINGLE_THREAD_ENVIRONMENT):
            futures = _submit_all(pool, tasks)
        yield from _unordered(futures)


def _submit_all(
    executor: Executor, tasks: list[tuple[Callable[..., TaskResult], tuple]]
) -> list[Future[TaskResult]]:
    return [executor.submit(function, *arguments) for function, arguments in tasks]


def _unordered(futures: list[Future[TaskResult]]) -> Iterator[TaskResult]:
    try:
        for future in as_completed(futures):
            yield future.result()
    finally:
        for future in futures:
            future.cancel()
