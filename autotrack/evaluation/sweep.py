"""Parameter sweeps: one tracker preset, every combination of a grid of parameter values, on
every sequence of a benchmark; resumable, locally or on a Dask cluster.

A grid is a list of axes `name=v1,v2,...` over `TrackerParams` fields (`phi=0.2,0.3,0.4`,
`delta=0.1,0.2`); the sweep runs the product of the axes. The unit of work is
`run_combination(label, params, sequence) -> TaskResult`, a pure, picklable function like the
benchmark's `run_task`, so the same executors run it (inline, a local process pool, or
`autotrack.evaluation.distributed.cluster_executor`). Results are saved as they arrive:

- ``DIR/runs/<label>/params.json``: the full parameters of the combination;
- ``DIR/runs/<label>/<sequence>.txt`` and ``.time.json``: boxes and tracking times, the
  benchmark's result files (`autotrack.evaluation.runs`), so an interrupted sweep resumes
  where it stopped;
- ``DIR/sweep.csv``, ``DIR/sweep.md``, ``DIR/sweep.json``: P@20, AUC and fps per combination;
- ``DIR/sweep.png``: the same as bars, one panel per figure.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import re
import typing
from collections.abc import Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from autotrack.errors import InputError
from autotrack.evaluation.benchmark import BenchmarkRun, TrackerSummary, summarize_run
from autotrack.evaluation.datasets import Sequence as BenchmarkSequence
from autotrack.evaluation.peers import AutoTrackPeer
from autotrack.evaluation.runs import TaskResult, run_resumable, track_timed
from autotrack.extras import has_module
from autotrack.hybrid.factory import NANOTRACK, BoxesOf, make_tracker
from autotrack.io.atomic import write_figure, write_text
from autotrack.io.csv_table import write_csv as write_table
from autotrack.params import TrackerParams

RUNS_FOLDER = "runs"
"""Sub-folder of the sweep's output folder holding one folder per combination."""

_SAFE_VALUE = re.compile(r"^[A-Za-z0-9_.+-]+$")

GridValue = float | int | bool | str


@dataclass(frozen=True)
class GridAxis:
    """One swept parameter and the values it takes."""

    name: str
    """A TrackerParams field name."""
    values: tuple[GridValue, ...]
    """Its values, in the order given."""


@dataclass(frozen=True)
class Combination:
    """One point of the grid: the swept values and the full parameters they give."""

    values: tuple[tuple[str, GridValue], ...]
    """(parameter, value) pairs in grid-axis order."""
    params: TrackerParams
    """The base preset with these values replaced."""
    tracker: str | None = None
    """`hybrid`: the parameters are the hybrid's correlation filter's; None: AutoTrack's."""

    @property
    def label(self) -> str:
        """File-safe name, e.g. 'phi=0.2_delta=0.1' (the folder of its results)."""
        return "_".join(f"{name}={format_value(value)}" for name, value in self.values)


def format_value(value: GridValue) -> str:
    """Shortest text of a grid value (floats as Python's repr: 0.2, 1e-05)."""
    return repr(value) if isinstance(value, float) else str(value)


def _field_types() -> dict[str, object]:
    hints = typing.get_type_hints(TrackerParams)
    return {field.name: hints[field.name] for field in dataclasses.fields(TrackerParams)}


def _convert(name: str, kind: object, text: str) -> GridValue:
    """One grid value as the field's type; InputError naming the field when it does not fit."""
    try:
        if kind is bool:
            lowered = text.lower()
            if lowered not in ("true", "false", "1", "0"):
                raise ValueError(text)
            return lowered in ("true", "1")
        if kind is int:
            return int(text)
        if kind is float:
            value = float(text)
            if not math.isfinite(value):
                raise ValueError(text)
            return value
        choices = typing.get_args(kind)
        if choices and all(isinstance(choice, str) for choice in choices):
            if text not in choices:
                raise ValueError(text)
            return text
    except ValueError:
        expected = {bool: "true or false", int: "an integer", float: "a finite number"}.get(
            kind, " / ".join(typing.get_args(kind))
        )
        raise InputError(f"--grid {name}: {text!r} is not {expected}") from None
    raise InputError(f"--grid {name}: this parameter cannot be swept (type {kind})")


def parse_grid(specs: Sequence[str]) -> tuple[GridAxis, ...]:
    """'name=v1,v2,...' strings -> grid axes over TrackerParams fields, values typed per field."""
    import difflib

    types = _field_types()
    axes: list[GridAxis] = []
    for spec in specs:
        name, separator, values_text = spec.partition("=")
        name = name.strip()
        if not separator or not name:
            raise InputError(f"--grid must be NAME=V1,V2,... (e.g. phi=0.2,0.3), got {spec!r}")
        if name not in types:
            close = difflib.get_close_matches(name, list(types), n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise InputError(f"--grid {name}: not a tracker parameter{hint}")
        if name in ("colour_feature", "colour_table_path"):
            raise InputError(f"--grid {name}: choose the colour feature with --color-names")
        if any(axis.name == name for axis in axes):
            raise InputError(f"--grid {name} is given twice")
        texts = [text.strip() for text in values_text.split(",") if text.strip()]
        if not texts:
            raise InputError(f"--grid {name}: no values")
        values = tuple(dict.fromkeys(_convert(name, types[name], text) for text in texts))
        axes.append(GridAxis(name, values))
    if not axes:
        raise InputError("give at least one --grid NAME=V1,V2,...")
    return tuple(axes)


def grid_combinations(
    base: TrackerParams, axes: Sequence[GridAxis], tracker: str | None = None
) -> tuple[Combination, ...]:
    """Every combination of the axes' values (the first axis varies slowest), as parameters of
    `tracker` (None: AutoTrack; `hybrid`: its correlation filter; NanoTrack has no
    TrackerParams and is refused).

    InputError when a combination gives invalid parameters (TrackerParams checks them).
    """
    if tracker == NANOTRACK:
        fields = ", ".join(axis.name for axis in axes) or "none"
        raise InputError(
            f"nanotrack uses no TrackerParams, so a sweep of them ({fields}) changes nothing: "
            "sweep an AutoTrack preset or hybrid, or compare trackers with autotrack bench"
        )
    combinations = []
    for values in itertools.product(*(axis.values for axis in axes)):
        pairs = tuple(zip((axis.name for axis in axes), values, strict=True))
        combination = Combination(pairs, dataclasses.replace(base, **dict(pairs)), tracker)
        if not all(_SAFE_VALUE.match(format_value(value)) for _, value in pairs):
            raise InputError(f"--grid values must be plain numbers or words: {combination.label}")
        combinations.append(combination)
    return tuple(combinations)


def run_combination(
    label: str, params: TrackerParams, sequence: BenchmarkSequence, tracker: str | None = None
) -> TaskResult:
    """Track one sequence with one combination's parameters (of `tracker`, None: AutoTrack),
    timing only the tracker calls (the benchmark's `run_task` for a parameter set instead of a
    tracker name)."""
    if tracker is None:
        return track_timed(label, lambda: AutoTrackPeer(params), sequence)
    return track_timed(label, lambda: BoxesOf(make_tracker(tracker, params)), sequence)


def colour_feature_label(params: TrackerParams) -> str:
    """The colour feature as the benchmark records it: 'lab11', 'none' or 'table:<path>'."""
    if params.colour_feature == "table":
        return f"table:{params.colour_table_path}"
    return params.colour_feature


def _params_json(combination: Combination) -> str:
    """The combination's params.json: its parameters, and its tracker when not AutoTrack (the
    same parameters of another tracker are other results)."""
    recorded = dataclasses.asdict(combination.params)
    if combination.tracker is not None:
        recorded["tracker"] = combination.tracker
    return json.dumps(recorded, sort_keys=True, indent=1) + "\n"


def _claim_folder(runs_dir: Path, combination: Combination) -> None:
    """Create the combination's folder with its params.json; refuse one holding other params."""
    folder = runs_dir / combination.label
    params_path = folder / "params.json"
    expected = _params_json(combination)
    if params_path.is_file() and params_path.read_text(encoding="utf-8") != expected:
        raise InputError(
            f"{folder} holds results of other parameters (another --preset or --color-names): "
            f"use another --out, or delete that folder to rerun it"
        )
    folder.mkdir(parents=True, exist_ok=True)
    write_text(params_path, expected)


@dataclass(frozen=True, eq=False)
class SweepRun:
    """Results of every (combination, sequence) pair of a sweep, new or resumed."""

    combinations: tuple[Combination, ...]
    """The grid, in order."""
    benchmark: BenchmarkRun
    """The results as a benchmark run whose 'trackers' are the combination labels."""


def run_sweep(
    sequences: Sequence[BenchmarkSequence],
    combinations: Sequence[Combination],
    out_dir: str | Path,
    *,
    jobs: int = 1,
    executor: Executor | None = None,
    progress: bool = True,
) -> SweepRun:
    """Run every combination on every sequence, skipping pairs already saved under `out_dir`.

    jobs=1 tracks in this process, jobs > 1 in that many single-thread worker processes;
    `executor` (e.g. a Dask cluster's) replaces both.
    """
    if jobs < 1:
        raise InputError(f"--jobs must be at least 1, got {jobs}")
    if not combinations:
        raise InputError("the grid has no combinations")
    names = [sequence.name for sequence in sequences]
    if len(set(names)) != len(names):
        raise InputError("sequence names must be unique in a sweep (they name the results)")
    runs_dir = Path(out_dir) / RUNS_FOLDER
    for combination in combinations:
        _claim_folder(runs_dir, combination)
    colour_features = {c.label: colour_feature_label(c.params) for c in combinations}
    tasks = {c.label: (c.params, c.tracker) for c in combinations}
    runs = run_resumable(
        [combination.label for combination in combinations],
        sequences,
        runs_dir,
        colour_features,
        lambda label, sequence: (
            run_combination,
            (label, tasks[label][0], sequence, tasks[label][1]),
        ),
        jobs=jobs,
        executor=executor,
        progress=progress,
        description="sweep",
    )
    benchmark = BenchmarkRun(
        trackers=tuple(c.label for c in combinations),
        sequences=tuple(sequences),
        results=runs.results,
        colour_features=colour_features,
        computed=runs.computed,
        resumed=runs.resumed,
    )
    return SweepRun(tuple(combinations), benchmark)


# ---------------------------------------------------------------------------------------------
# Tables and plot


@dataclass(frozen=True)
class SweepRow:
    """Scores of one combination over all sequences of the sweep."""

    values: tuple[tuple[str, GridValue], ...]
    """(parameter, value) pairs."""
    label: str
    """The combination's label."""
    precision: float
    """Mean precision at 20 px over the sequences."""
    auc: float
    """Mean success AUC over the sequences."""
    fps_median: float
    """Median over sequences of the tracking-only fps."""
    fps_overall: float
    """All frames over all tracking time."""
    frames: int
    """Frames tracked per combination."""


def sweep_rows(sweep: SweepRun) -> list[SweepRow]:
    """One row per combination, in grid order."""
    summaries: Mapping[str, TrackerSummary] = summarize_run(sweep.benchmark)
    rows = []
    for combination in sweep.combinations:
        summary = summaries[combination.label]
        rows.append(
            SweepRow(
                values=combination.values,
                label=combination.label,
                precision=summary.overall.precision,
                auc=summary.overall.auc,
                fps_median=summary.fps_median,
                fps_overall=summary.fps_overall,
                frames=sum(summary.frames.values()),
            )
        )
    return rows


_HEADER = ("P@20", "AUC", "fps (median)", "fps (all frames)")


def _cells(row: SweepRow) -> list[str]:
    return [format_value(value) for _, value in row.values] + [
        f"{row.precision:.3f}",
        f"{row.auc:.3f}",
        f"{row.fps_median:.1f}",
        f"{row.fps_overall:.1f}",
    ]


def format_markdown(rows: Sequence[SweepRow]) -> str:
    """A markdown table: one column per swept parameter, then P@20, AUC and the two fps."""
    header = [name for name, _ in rows[0].values] + list(_HEADER)
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_cells(row)) + " |" for row in rows]
    return "\n".join(lines)


def write_csv(path: Path, rows: Sequence[SweepRow]) -> None:
    """The table as CSV, full precision (parameters, precision, auc, fps_median, fps_overall,
    frames)."""
    header = [name for name, _ in rows[0].values]
    header += ["precision", "auc", "fps_median", "fps_overall", "frames"]
    table = [
        [format_value(value) for _, value in row.values]
        + [
            f"{row.precision:.6f}",
            f"{row.auc:.6f}",
            f"{row.fps_median:.3f}",
            f"{row.fps_overall:.3f}",
            row.frames,
        ]
        for row in rows
    ]
    write_table(path, header, table, line_end="\r\n")


def write_plot(path: Path, rows: Sequence[SweepRow], title: str = "") -> Path:
    """P@20, AUC and median fps per combination as three bar panels (PNG)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    labels = [row.label.replace("_", "\n") for row in rows]
    positions = np.arange(len(rows))
    figure = Figure(figsize=(max(6.0, 0.8 * len(rows) + 2.0), 8.0), dpi=110)
    FigureCanvasAgg(figure)
    panels = figure.subplots(3, 1, sharex=True)
    series = (
        ("Precision @ 20 px", [row.precision for row in rows], (0.0, 1.0)),
        ("Success AUC", [row.auc for row in rows], (0.0, 1.0)),
        ("fps (median, tracking only)", [row.fps_median for row in rows], None),
    )
    for axes, (name, values, limits) in zip(panels, series, strict=True):
        bars = axes.bar(positions, values, color="tab:blue")
        axes.bar_label(bars, fmt="%.3f" if limits else "%.1f", fontsize=7)
        axes.set_ylabel(name)
        if limits:
            axes.set_ylim(*limits)
        axes.grid(axis="y", alpha=0.3)
    panels[-1].set_xticks(positions, labels, fontsize=7)
    if title:
        panels[0].set_title(title)
    figure.tight_layout()
    return write_figure(path, figure)


def write_outputs(
    out_dir: Path, rows: Sequence[SweepRow], *, title: str = "", meta: Mapping | None = None
) -> list[Path]:
    """sweep.csv, sweep.md, sweep.json and (with matplotlib, the plots extra) sweep.png in
    `out_dir`; returns the paths written."""
    out_dir.mkdir(parents=True, exist_ok=True)
    csv_path, md_path = out_dir / "sweep.csv", out_dir / "sweep.md"
    json_path, png_path = out_dir / "sweep.json", out_dir / "sweep.png"
    write_csv(csv_path, rows)
    write_text(md_path, format_markdown(rows) + "\n")
    summary = {
        **(meta or {}),
        "notes": "precision: mean P@20 over sequences; auc: mean success AUC; fps_median: median "
        "over sequences of tracking-only fps; fps_overall: all frames / all tracking time",
        "combinations": [
            {
                "label": row.label,
                "values": dict(row.values),
                "precision": round(row.precision, 6),
                "auc": round(row.auc, 6),
                "fps_median": round(row.fps_median, 3),
                "fps_overall": round(row.fps_overall, 3),
                "frames": row.frames,
            }
            for row in rows
        ],
    }
    write_text(json_path, json.dumps(summary, indent=2) + "\n")
    written = [csv_path, md_path, json_path]
    if has_module("matplotlib"):  # the plots extra
        written.append(write_plot(png_path, rows, title))
    return written


def limit_frames(sequences: Sequence[BenchmarkSequence], frames: int) -> list[BenchmarkSequence]:
    """Each sequence cut to its first `frames` frames (quick sweeps); InputError if frames < 2."""
    if frames < 2:
        raise InputError(f"--frames must be at least 2, got {frames}")
    return [
        dataclasses.replace(
            sequence,
            frame_paths=sequence.frame_paths[:frames],
            ground_truth=sequence.ground_truth[:frames],
        )
        for sequence in sequences
    ]
