"""One-pass evaluation: every tracker on every sequence, resumable, in parallel; its scores,
tables and plots.

The unit of work is `run_task(tracker_name, sequence, colour_table_path) -> TaskResult`: a pure,
picklable function of one (tracker, sequence) pair. `run_benchmark` maps it over the pairs not
already saved, inline (jobs=1), in a local process pool (jobs > 1) or on any
`concurrent.futures.Executor` passed in (a distributed engine's executor can take the pool's
place), and saves each result as it arrives (`autotrack.evaluation.runs`: the files, resuming,
and single-thread timing of the tracker calls only).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

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
from autotrack.evaluation.runs import TaskResult, run_resumable, track_timed

DEFAULT_OUT_DIR = Path("results")
"""Where results go when no --out is given (relative to the current directory)."""


def run_task(
    tracker_name: str,
    sequence: BenchmarkSequence,
    colour_table_path: str | Path | None = None,
) -> TaskResult:
    """Track one sequence from its first ground-truth box; time only the tracker calls."""
    return track_timed(
        tracker_name, lambda: make_tracker(tracker_name, colour_table_path), sequence
    )


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
    runs = run_resumable(
        tracker_names,
        sequences,
        out_dir,
        colour_features,
        lambda name, sequence: (run_task, (name, sequence, colour_table)),
        jobs=jobs,
        executor=executor,
        progress=progress,
        description="bench",
    )
    return BenchmarkRun(
        trackers=tracker_names,
        sequences=tuple(sequences),
        results=runs.results,
        colour_features=colour_features,
        computed=runs.computed,
        resumed=runs.resumed,
    )


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


def summary_json(
    summaries: Mapping[str, TrackerSummary],
    root: str | Path | None = None,
    machine: Mapping[str, object] | None = None,
) -> dict:
    """The machine-readable summary written by `autotrack bench --json`. `machine`: where the
    fps were measured (`autotrack.machine.describe_machine`; None: not recorded, e.g. on a
    cluster's workers)."""

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
        "machine": dict(machine) if machine is not None else None,
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
