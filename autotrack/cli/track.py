"""`autotrack track SEQUENCE`: run one tracker over a sequence and write its boxes."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from autotrack.cli.checks import (
    add_session_arguments,
    add_tracker_argument,
    check_output_file,
    check_session_file,
    chosen_tracker,
    init_box,
    session_recording,
)
from autotrack.cli.live import add_live_arguments, check_source, run_track_live
from autotrack.cli.timing import STARTUP_FRAMES, StartupClock
from autotrack.errors import InputError
from autotrack.evaluation.datasets import GROUND_TRUTH_FILE
from autotrack.evaluation.metrics import score_sequence
from autotrack.io.frames import open_frames
from autotrack.io.live import source_argument
from autotrack.io.otb_boxes import read_boxes, write_boxes


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "track",
        help="track one target through a sequence",
        description=(
            "Track one target through SEQUENCE (a folder of images, a video file, or a benchmark "
            "sequence folder with img/ and groundtruth_rect.txt). Boxes are x,y,w,h in the "
            "benchmarks' 1-based pixel convention, for --init and for the output alike."
        ),
    )
    parser.add_argument(
        "sequence",
        type=source_argument,
        help="folder of images, video, or sequence folder; with --realtime a camera index, "
        "stream URL or video",
    )
    parser.add_argument(
        "--init",
        type=str,
        default=None,
        help="initial box x,y,w,h (1-based, as groundtruth_rect.txt); default: its first row",
    )
    add_tracker_argument(parser)
    parser.add_argument(
        "--color-names",
        "--colour-table",
        dest="colour_table",
        type=Path,
        default=None,
        help="published Color Names table (.npy/.mat) instead of the built-in colour feature",
    )
    parser.add_argument("--out", type=Path, default=None, help="write boxes here (x,y,w,h rows)")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    add_session_arguments(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_live_arguments(parser)
    parser.add_argument(
        "--fps", type=float, default=None, help="with --realtime: play a video at this rate"
    )
    parser.set_defaults(func=run)


def _ground_truth(sequence: Path) -> np.ndarray | None:
    path = sequence / GROUND_TRUTH_FILE
    return read_boxes(path) if sequence.is_dir() and path.is_file() else None


def run(args: argparse.Namespace) -> int:
    clock = StartupClock()
    from autotrack.pipeline import Pipeline

    check_output_file(args.out, "--out", force=args.force)
    check_session_file(args.session)
    if args.session is not None and args.realtime:
        raise InputError("--session records sequences here; live runs: autotrack localize")
    if args.colour_table is not None and not args.colour_table.is_file():
        raise InputError(f"Color Names table not found: {args.colour_table}")
    check_source(args)
    tracker, params = chosen_tracker(args, args.colour_table)
    if args.realtime:
        return run_track_live(args, tracker, params)
    frames = open_frames(args.sequence)
    ground_truth = _ground_truth(args.sequence)
    if args.init is not None:
        first_box = init_box(args.init, frames.frame_size)
    elif ground_truth is not None:
        first_box = ground_truth[0]
    else:
        raise InputError(
            f"{args.sequence} has no {GROUND_TRUTH_FILE}: give the initial box with --init x,y,w,h"
        )
    boxes = np.full((len(frames), 4), np.nan)
    progress = tqdm(
        total=len(frames), unit="frame", desc=frames.name, disable=args.quiet or len(frames) < 50
    )
    recording = session_recording(args)
    with (
        frames,
        progress,
        Pipeline(frames, params, tracker=tracker, recording=recording, map_window=0) as pipeline,
    ):
        target_id = pipeline.add_target(0, tuple(first_box), landmark_id=None)
        for outcome in pipeline.run():
            boxes[outcome.frame_index] = outcome.tracks[target_id].box
            progress.update()
            clock.tick()
        tracking_seconds = float(np.nansum(pipeline.frame_seconds[STARTUP_FRAMES:]))
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_boxes(args.out, boxes)
    timing = clock.report("tracking (tracker time only)", tracking_seconds)
    print(f"frames: {len(frames)} · {timing}")
    if ground_truth is not None and len(ground_truth) == len(boxes):
        score = score_sequence(frames.name, boxes, ground_truth)
        print(f"precision@20px: {score.precision:.3f}  success AUC: {score.auc:.3f}")
    elif ground_truth is not None:
        print(
            f"ground truth has {len(ground_truth)} rows for {len(boxes)} frames: not scored",
            file=sys.stderr,
        )
    if args.out is not None:
        print(f"boxes written to {args.out}")
    if args.session is not None:
        print(f"session recorded to {args.session}")
    return 0
