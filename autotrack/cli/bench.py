"""`autotrack bench`: one-pass evaluation of trackers on a benchmark folder."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from autotrack.evaluation.peers import TRACKER_NAMES

DEFAULT_TRACKERS = ",".join(TRACKER_NAMES)


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add the `bench` sub-command."""
    parser = subparsers.add_parser(
        "bench",
        help="run trackers on a benchmark and score them (OPE precision / success)",
        description=(
            "Run every tracker on every sequence of a benchmark folder (OTB/DTB70-style, "
            "UAV123, UAVDT-SOT, VisDrone-SOT, or a folder of these), save per-sequence boxes "
            "in DIR/<tracker>/<sequence>.txt and print precision at 20 px, success AUC and fps. "
            "Sequences already saved in DIR are not rerun."
        ),
    )
    parser.add_argument("root", type=Path, help="benchmark folder (layout is auto-detected)")
    parser.add_argument(
        "--trackers",
        default=DEFAULT_TRACKERS,
        metavar="NAMES",
        help=f"comma-separated tracker names (default: {DEFAULT_TRACKERS})",
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=1,
        metavar="N",
        help="sequences tracked in parallel processes (default 1)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        default=Path("results"),
        help="results folder (default: ./results); also used to resume an interrupted run",
    )
    parser.add_argument(
        "--json", type=Path, metavar="FILE", help="write a machine-readable summary to this file"
    )
    parser.add_argument(
        "--plots", action="store_true", help="write precision/success plots to DIR/plots/"
    )
    parser.add_argument("--force", action="store_true", help="replace an existing --json file")
    add_run_arguments(parser)
    parser.set_defaults(func=run)


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """--color-names, --scheduler and --no-progress: how a batch of tracking runs is run
    (shared by `bench` and `sweep`)."""
    parser.add_argument(
        "--color-names",
        "--colour-table",
        dest="colour_table",
        type=Path,
        metavar="PATH",
        help="published Color Names table (32768 x 10, .npy or .mat) for the AutoTrack variants",
    )
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="tcp://HOST:PORT",
        help="run on this Dask scheduler's workers (they need the data at the same path)",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def run(args: argparse.Namespace) -> int:
    """Run the benchmark described by the parsed arguments."""
    from autotrack.cli.checks import check_output_file
    from autotrack.errors import InputError
    from autotrack.evaluation.benchmark import (
        format_table,
        run_benchmark,
        summarize_run,
        summary_json,
        validate_tracker_names,
        write_run_plots,
    )
    from autotrack.evaluation.datasets import load_sequences
    from autotrack.evaluation.distributed import cluster_executor_for
    from autotrack.extras import require_extra
    from autotrack.io.atomic import write_text
    from autotrack.machine import describe_machine, machine_line

    if args.plots:
        require_extra("matplotlib", "plots", "--plots")
    check_output_file(args.json, "--json", force=args.force)
    trackers = validate_tracker_names(args.trackers.split(","))
    if args.jobs < 1:
        raise InputError(f"--jobs must be at least 1, got {args.jobs}")
    sequences = load_sequences(args.root)
    with cluster_executor_for(args) as executor:
        run_result = run_benchmark(
            sequences,
            trackers,
            args.out,
            jobs=args.jobs,
            colour_table=args.colour_table,
            progress=not args.no_progress,
            executor=executor,
        )
    summaries = summarize_run(run_result)
    # fps depend on the CPU: a local run names this machine, a cluster's workers are not known
    machine = describe_machine() if args.scheduler is None else None
    print(
        f"{len(sequences)} sequences, {sum(len(s) for s in sequences)} frames; "
        f"{run_result.computed} runs tracked, {run_result.resumed} resumed from {args.out}"
    )
    print(format_table(summaries))
    if machine is None:
        print("fps measured on the cluster's workers (their CPUs are not recorded)")
    else:
        earlier = f" (the {run_result.resumed} resumed runs': where they ran)"
        print(f"fps measured on: {machine_line(machine)}" + (earlier if run_result.resumed else ""))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        document = summary_json(summaries, args.root, machine)
        write_text(args.json, json.dumps(document, indent=2) + "\n")
        print(f"summary: {args.json}")
    if args.plots:
        written = write_run_plots(summaries, args.out / "plots", title=args.root.name)
        print(f"plots: {len(written)} PNG files in {args.out / 'plots'}")
    return 0
