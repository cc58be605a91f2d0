"""One-pass evaluation runner: every tracker on every sequence, resumable, in parallel.

The unit of work is `run_task(tracker_name, sequence, colour_table_path) -> TaskResult`: a pure,
picklable function of one (tracker, sequence) pair. `run_benchmark` maps it over the pairs not
already saved, inline (jobs=1), in a local process pool (jobs > 1) or on any
`concurrent.futures.Executor` passed in (a distributed engine's executor can take the pool's
place), and saves each result as it arrives:

- ``DIR/<tracker>/<sequence>.txt``: one x,y,w,h row per frame, 1-based (benchmark convention),
  the file other toolkits read;
- ``DIR/<tracker>/<sequence>.time.json``: per-frame tracking times and the tracker's colour
  feature. A pair is resumed (not rerun) when both files exist, the box file has one row per
  frame and the colour feature matches.

Timing is the wall time of the tracker's init/update calls only (not frame decoding), with
OpenCV, numba and BLAS limited to one thread per process.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from autotrack.errors import InputError
from autotrack.evaluation.datasets import Sequence as BenchmarkSequence
from autotrack.evaluation.metrics import (
    PRECISION_THRESHOLDS,
    SUCCESS_THRESHOLDS,
    SequenceScore,
    SummaryScore,
    score_sequence,
    summarize,
    summarize_by_attribute,
    summarize_by_dataset,
)
from autotrack.evaluation.peers import TRACKER_NAMES, colour_feature_of, make_tracker
from autotrack.io import otb_boxes
from autotrack.io.atomic import write_text

DEFAULT_OUT_DIR = Path("results")
"""Where results go when no --out is given (relative to the current directory)."""

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
    """Tracker name."""
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


def run_task(
    tracker_name: str,
    sequence: BenchmarkSequence,
    colour_table_path: str | Path | None = None,
) -> TaskResult:
    """Track one sequence from its first ground-truth box; time only the tracker calls."""
    count = len(sequence)
    boxes = np.empty((count, 4), dtype=np.float64)
    times = np.empty(count, dtype=np.float64)
    init_box = sequence.init_box
    with sequence.frames() as frames, single_thread():
        tracker = make_tracker(tracker_name, colour_table_path)
        for index in range(count):
            frame = frames.read(index)
            start = time.perf_counter()
            box = tracker.init(frame, init_box) if index == 0 else tracker.update(frame)
            times[index] = time.perf_counter() - start
            boxes[index] = box
    return TaskResult(tracker_name, sequence.name, boxes, times)


def result_paths(out_dir: Path, tracker: str, sequence: str) -> tuple[Path, Path]:
    """The box file and the timing file of one (tracker, sequence) pair."""
    folder = Path(out_dir) / tracker
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
    out_dir: Path, tracker: str, sequence: BenchmarkSequence, colour_feature: str | None
) -> TaskResult | None:
    """A saved result for the pair, or None when it is missing, incomplete or from another
    colour feature (then the pair is rerun)."""
    boxes_path, timing_path = result_paths(out_dir, tracker, sequence.name)
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
    return TaskResult(tracker, sequence.name, boxes, times)


@contextmanager
def _environment(variables: Mapping[str, str]) -> Iterator[None]:
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


@dataclass(frozen=True, eq=False)
class BenchmarkRun:
    """Results of every (tracker, sequence) pair of a run, new or resumed."""

    trackers: tuple[str, ...]
    """Tracker names in the order asked for."""
    sequences: tuple[BenchmarkSequence, ...]
    """The sequences, in loading order."""
    results: dict[tuple[str, str], TaskResult]
    """(tracker, sequence name) -> result."""
    colour_features: dict[str, str | None]
    """Tracker -> colour feature used (None for the OpenCV peers)."""
    computed: int = 0
    """Pairs tracked in this run."""
    resumed: int = 0
    """Pairs loaded from the output folder."""


def validate_tracker_names(names: Sequence[str]) -> tuple[str, ...]:
    """Lower-cased, de-duplicated tracker names; InputError for an unknown name."""
    cleaned = tuple(dict.fromkeys(name.strip().lower() for name in names if name.strip()))
    unknown = [name for name in cleaned if name not in TRACKER_NAMES]
    if unknown or not cleaned:
        raise InputError(
            f"unknown tracker(s) {', '.join(unknown) or '(none given)'}; "
            f"choose from {', '.join(TRACKER_NAMES)}"
        )
    return cleaned


def run_benchmark(
    sequences: Sequence[BenchmarkSequence],
    trackers: Sequence[str],
    out_dir: str | Path = DEFAULT_OUT_DIR,
    *,
    jobs: int = 1,
    colour_table: str | Path | None = None,
    progress: bool = True,
    executor: Executor | None = None,
) -> BenchmarkRun:
    """Run every tracker on every sequence, skipping pairs already saved in `out_dir`.

    jobs=1 tracks in this process; jobs > 1 uses that many worker processes (spawned with one
    thread each). `executor`, when given, replaces both (any concurrent.futures.Executor whose
    workers can import autotrack).
    """
    tracker_names = validate_tracker_names(trackers)
    if jobs < 1:
        raise InputError(f"--jobs must be at least 1, got {jobs}")
    if colour_table is not None and not Path(colour_table).is_file():
        raise InputError(f"colour table not found: {colour_table}")
    names = [sequence.name for sequence in sequences]
    if len(set(names)) != len(names):
        raise InputError("sequence names must be unique in a benchmark run (they name the results)")
    out_dir = Path(out_dir)
    colour_features = {name: colour_feature_of(name, colour_table) for name in tracker_names}
    results: dict[tuple[str, str], TaskResult] = {}
    pending: list[tuple[str, BenchmarkSequence]] = []
    for name in tracker_names:
        for sequence in sequences:
            saved = load_result(out_dir, name, sequence, colour_features[name])
            if saved is None:
                pending.append((name, sequence))
            else:
                results[(name, sequence.name)] = saved
    resumed = len(results)
    # Longest sequences first so parallel workers finish together.
    pending.sort(key=lambda task: -len(task[1]))

    with tqdm(total=len(pending), desc="bench", unit="run", disable=not progress) as bar:
        for result in _execute(pending, colour_table, jobs, executor):
            save_result(out_dir, result, colour_features[result.tracker])
            results[(result.tracker, result.sequence)] = result
            bar.set_postfix_str(f"{result.tracker} {result.sequence} {result.fps:.1f} fps")
            bar.update()
    return BenchmarkRun(
        trackers=tracker_names,
        sequences=tuple(sequences),
        results=results,
        colour_features=colour_features,
        computed=len(pending),
        resumed=resumed,
    )


def _execute(
    tasks: list[tuple[str, BenchmarkSequence]],
    colour_table: str | Path | None,
    jobs: int,
    executor: Executor | None,
) -> Iterator[TaskResult]:
    if not tasks:
        return
    if executor is None and jobs == 1:
        for tracker, sequence in tasks:
            yield run_task(tracker, sequence, colour_table)
        return
    if executor is not None:
        yield from _map_unordered(executor, tasks, colour_table)
        return
    with (
        _environment(SINGLE_THREAD_ENVIRONMENT),
        ProcessPoolExecutor(
            max_workers=min(jobs, len(tasks)), mp_context=get_context("spawn")
        ) as pool,
    ):
        yield from _map_unordered(pool, tasks, colour_table)


def _map_unordered(
    executor: Executor, tasks: list[tuple[str, BenchmarkSequence]], colour_table: str | Path | None
) -> Iterator[TaskResult]:
    futures: list[Future[TaskResult]] = [
        executor.submit(run_task, tracker, sequence, colour_table) for tracker, sequence in tasks
    ]
    try:
        for future in as_completed(futures):
            yield future.result()
    finally:
        for future in futures:
            future.cancel()


@dataclass(frozen=True, eq=False)
class TrackerSummary:
    """Scores and speed of one tracker over a run."""

    name: str
    """Tracker name."""
    colour_feature: str | None
    """Colour feature used (None for OpenCV peers)."""
    overall: SummaryScore
    """Curves averaged over all sequences."""
    sequences: dict[str, SequenceScore]
    """Per-sequence scores by sequence name."""
    frames: dict[str, int]
    """Per-sequence frame counts."""
    seconds: dict[str, float]
    """Per-sequence tracking time in seconds."""
    attributes: dict[str, SummaryScore] = field(default_factory=dict)
    """Per-attribute summaries (sequences having the attribute)."""
    datasets: dict[str, SummaryScore] = field(default_factory=dict)
    """Per-dataset summaries."""

    @property
    def fps(self) -> dict[str, float]:
        """Per-sequence frames per second of tracking time."""
        return {
            name: frames / self.seconds[name] if self.seconds[name] > 0 else math.inf
            for name, frames in self.frames.items()
        }

    @property
    def fps_median(self) -> float:
        """Median over sequences of the per-sequence fps."""
        return float(np.median(list(self.fps.values())))

    @property
    def fps_overall(self) -> float:
        """Frame-weighted fps: all frames over all tracking time."""
        seconds = sum(self.seconds.values())
        return sum(self.frames.values()) / seconds if seconds > 0 else math.inf


def summarize_run(run: BenchmarkRun) -> dict[str, TrackerSummary]:
    """Score every tracker of a run, in the run's tracker order."""
    summaries = {}
    for name in run.trackers:
        scores = [
            score_sequence(
                sequence.name,
                run.results[(name, sequence.name)].boxes,
                sequence.ground_truth,
                sequence.attributes,
                sequence.dataset,
            )
            for sequence in run.sequences
        ]
        tasks = [run.results[(name, sequence.name)] for sequence in run.sequences]
        summaries[name] = TrackerSummary(
            name=name,
            colour_feature=run.colour_features.get(name),
            overall=summarize(scores),
            sequences={score.name: score for score in scores},
            frames={task.sequence: task.frames for task in tasks},
            seconds={task.sequence: task.seconds for task in tasks},
            attributes=summarize_by_attribute(scores),
            datasets=summarize_by_dataset(scores),
        )
    return summaries


def _number(value: float, digits: int = 4) -> float | None:
    """JSON-safe rounding: None for NaN and infinities."""
    return round(float(value), digits) if math.isfinite(value) else None


def summary_json(summaries: Mapping[str, TrackerSummary], root: str | Path | None = None) -> dict:
    """The machine-readable summary written by `autotrack bench --json`."""

    def block(summary: SummaryScore) -> dict:
        return {
            "precision": _number(summary.precision),
            "auc": _number(summary.auc),
            "sequences": summary.sequences,
        }

    trackers = {}
    for name, summary in summaries.items():
        fps = summary.fps
        trackers[name] = {
            "precision": _number(summary.overall.precision),
            "auc": _number(summary.overall.auc),
            "fps": _number(summary.fps_median, 2),
            "fps_overall": _number(summary.fps_overall, 2),
            "frames": sum(summary.frames.values()),
            "colour_feature": summary.colour_feature,
            "precision_curve": [_number(v) for v in summary.overall.precision_curve],
            "success_curve": [_number(v) for v in summary.overall.success_curve],
            "datasets": {key: block(value) for key, value in summary.datasets.items()},
            "attributes": {key: block(value) for key, value in summary.attributes.items()},
            "sequences": {
                sequence: {
                    "precision": _number(score.precision),
                    "auc": _number(score.auc),
                    "fps": _number(fps[sequence], 2),
                    "frames": summary.frames[sequence],
                    "dataset": score.dataset,
                }
                for sequence, score in summary.sequences.items()
            },
        }
    return {
        "root": str(root) if root is not None else None,
        "thresholds": {
            "precision": PRECISION_THRESHOLDS.tolist(),
            "success": [round(float(t), 4) for t in SUCCESS_THRESHOLDS],
        },
        "notes": (
            "precision: at 20 px; auc: mean of the success curve; fps: median over sequences "
            "of tracking-only frames per second; fps_overall: all frames / all tracking time"
        ),
        "trackers": trackers,
    }


def format_table(summaries: Mapping[str, TrackerSummary]) -> str:
    """A plain-text table: tracker, precision at 20 px, AUC, median fps, frame-weighted fps."""
    header = ("tracker", "P@20", "AUC", "fps (median)", "fps (all frames)")
    rows = [
        (
            name,
            f"{summary.overall.precision:.3f}",
            f"{summary.overall.auc:.3f}",
            f"{summary.fps_median:.1f}",
            f"{summary.fps_overall:.1f}",
        )
        for name, summary in summaries.items()
    ]
    widths = [max(len(row[i]) for row in (header, *rows)) for i in range(len(header))]
    lines = [
        "  ".join(
            cell.ljust(width) if i == 0 else cell.rjust(width)
            for i, (cell, width) in enumerate(zip(row, widths, strict=True))
        )
        for row in (header, *rows)
    ]
    lines.insert(1, "  ".join("-" * width for width in widths))
    return "\n".join(lines)


def write_run_plots(
    summaries: Mapping[str, TrackerSummary], out_dir: str | Path, title: str = ""
) -> list[Path]:
    """Precision and success plots of a run (overall, per dataset, per attribute) as PNGs."""
    from autotrack.evaluation.plots import write_plots

    def regroup(kind: str) -> dict[str, dict[str, SummaryScore]]:
        grouped: dict[str, dict[str, SummaryScore]] = {}
        for tracker, summary in summaries.items():
            for key, score in getattr(summary, kind).items():
                grouped.setdefault(key, {})[tracker] = score
        return dict(sorted(grouped.items()))

    return write_plots(
        {name: summary.overall for name, summary in summaries.items()},
        out_dir,
        title=title,
        by_dataset=regroup("datasets"),
        by_attribute=regroup("attributes"),
    )
