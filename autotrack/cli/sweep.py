"""`autotrack sweep ROOT --preset P --grid NAME=V1,V2 ...`: a parameter grid on a benchmark."""

from __future__ import annotations

import argparse
from pathlib import Path

from autotrack.cli.bench import add_run_arguments
from autotrack.hybrid.factory import TRACKERS


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add the `sweep` sub-command."""
    parser = subparsers.add_parser(
        "sweep",
        help="run a tracker preset over a grid of parameter values on a benchmark",
        description=(
            "Run every combination of the --grid values (TrackerParams fields) on every "
            "sequence of a benchmark folder, locally or on a Dask cluster (--scheduler). "
            "Results are saved per run under DIR/runs/ and an interrupted sweep resumes. "
            "Writes DIR/sweep.csv, sweep.md, sweep.json and sweep.png (P@20, AUC, fps per "
            "combination)."
        ),
    )
    parser.add_argument("root", type=Path, help="benchmark folder (layout is auto-detected)")
    parser.add_argument(
        "--preset",
        default="autotrack",
        choices=TRACKERS,
        help="base parameters: an AutoTrack preset, or hybrid (its autotrack+ filter's); "
        "nanotrack has no TrackerParams and is refused",
    )
    parser.add_argument(
        "--grid",
        action="append",
        default=[],
        metavar="NAME=V1,V2,...",
        help="a swept parameter and its values, e.g. phi=0.2,0.3,0.4 (repeat for more axes)",
    )
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="results folder")
    parser.add_argument(
        "--frames",
        type=int,
        default=None,
        metavar="N",
        help="track only the first N frames of each sequence (quick sweeps)",
    )
    parser.add_argument(
        "--jobs", type=int, default=1, metavar="N", help="local worker processes (default 1)"
    )
    add_run_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the sweep described by the parsed arguments."""
    from autotrack.errors import InputError
    from autotrack.evaluation.datasets import load_sequences
    from autotrack.evaluation.distributed import cluster_executor_for
    from autotrack.evaluation.sweep import (
        format_markdown,
        grid_combinations,
        limit_frames,
        parse_grid,
        run_sweep,
        sweep_rows,
        write_outputs,
    )
    from autotrack.extras import has_module, install_hint
    from autotrack.hybrid.factory import SIAMESE_TRACKERS, tracker_params

    if args.colour_table is not None and not args.colour_table.is_file():
        raise InputError(f"colour table not found: {args.colour_table}")
    axes = parse_grid(args.grid)
    tracker = args.preset if args.preset in SIAMESE_TRACKERS else None
    base = tracker_params(args.preset, args.colour_table)
    combinations = grid_combinations(base, axes, tracker)
    sequences = load_sequences(args.root)
    if args.frames is not None:
        sequences = limit_frames(sequences, args.frames)
    with cluster_executor_for(args) as executor:
        sweep = run_sweep(
            sequences,
            combinations,
            args.out,
            jobs=args.jobs,
            executor=executor,
            progress=not args.no_progress,
        )
    rows = sweep_rows(sweep)
    frames = f"first {args.frames} frames of each" if args.frames else "all frames"
    print(
        f"{len(combinations)} combinations x {len(sequences)} sequences ({frames}, "
        f"{sum(len(s) for s in sequences)} frames); {sweep.benchmark.computed} runs tracked, "
        f"{sweep.benchmark.resumed} resumed from {args.out}"
    )
    print(format_markdown(rows))
    meta = {
        "root": str(args.root),
        "preset": args.preset,
        "grid": {axis.name: list(axis.values) for axis in axes},
        "frames_per_sequence": args.frames,
        "sequences": [sequence.name for sequence in sequences],
    }
    written = write_outputs(args.out, rows, title=f"{args.preset} on {args.root.name}", meta=meta)
    print("written: " + ", ".join(str(path) for path in written))
    if not has_module("matplotlib"):
        print(f"sweep.png not drawn: matplotlib is not installed ({install_hint('plots')})")
    return 0
