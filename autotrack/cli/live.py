"""`--realtime` for `autotrack track` and `autotrack localize`: the live reader in the commands.

Not a command of its own: `track` and `localize` add these options and hand over to
`run_track_live` / `run_localize_live` when `--realtime` is given.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from autotrack.cli.checks import init_box, session_recording
from autotrack.errors import BoxError, InputError


def add_live_arguments(parser: argparse.ArgumentParser) -> None:
    """--realtime, --frame-log (and, for track, --fps) on a command's parser."""
    parser.add_argument(
        "--realtime",
        action="store_true",
        help="live input: SOURCE is a camera index, an rtsp:// or http:// stream, or a video "
        "played at its frame rate; the tracker works on the newest frame and drops the rest",
    )
    parser.add_argument(
        "--frame-log",
        type=Path,
        default=None,
        metavar="CSV",
        help="with --realtime: every captured frame's capture time, whether it was processed "
        "or dropped, and its latency",
    )


def check_source(args: argparse.Namespace) -> None:
    """Refuse camera indices and streams without --realtime, and --frame-log without it or
    where it cannot be written (before any work starts)."""
    from autotrack.cli.checks import check_output_file
    from autotrack.io.live import describe_source, is_live_only

    if not args.realtime and is_live_only(args.sequence):
        raise InputError(f"{describe_source(args.sequence)} is live input: add --realtime")
    if not args.realtime and args.frame_log is not None:
        raise InputError("--frame-log records live runs: add --realtime")
    check_output_file(args.frame_log, "--frame-log", force=args.force)


def _finish(summary: Any, frame_log: Path | None) -> None:
    from autotrack.io.live import write_frame_log

    print(summary.describe())
    if frame_log is not None:
        frame_log.parent.mkdir(parents=True, exist_ok=True)
        write_frame_log(frame_log, summary)
        print(f"frame log written to {frame_log}")


def run_track_live(args: argparse.Namespace, tracker: str, params: Any) -> int:
    """`autotrack track SOURCE --realtime`: boxes of the processed frames, NaN rows for the
    dropped ones, and the drop/latency report."""
    from autotrack.io.live import LiveReader, describe_source
    from autotrack.io.otb_boxes import write_boxes
    from autotrack.pipeline.live import track_live, warm_up

    if args.init is None:
        raise InputError("live input has no ground truth: give the initial box with --init x,y,w,h")
    reader = LiveReader(args.sequence, fps=args.fps)
    try:
        first_box = init_box(args.init, reader.frame_size)
    except BoxError:
        reader.close()
        raise
    warm_up(params, reader.frame_size, [first_box], tracker)
    progress = tqdm(unit="frame", desc=describe_source(args.sequence), disable=args.quiet)
    with reader, progress:
        boxes, summary = track_live(
            reader,
            params,
            first_box,
            on_result=lambda frame, outcome: progress.update(),
            tracker=tracker,
        )
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_boxes(args.out, boxes)
        print(f"boxes written to {args.out} (one row per captured frame, NaN where dropped)")
    _finish(summary, args.frame_log)
    return 0


def _pose_options(args: argparse.Namespace) -> dict[str, Any]:
    """The pipeline's refinement and re-acquisition settings from `--no-refine` and
    `--no-reacquire`."""
    from autotrack.localization.reacquire import ReacquireParams
    from autotrack.localization.refine import RefineParams

    return {
        "refine_params": None if args.no_refine else RefineParams(),
        "reacquire_params": None if args.no_reacquire else ReacquireParams(),
    }


def run_localize_live(
    args: argparse.Namespace,
    *,
    scene: Any,
    scene_path: Path,
    init: Any,
    tracker: str,
    tracker_params: Any,
    localizer_params: Any,
    gt: Any,
) -> int:
    """`autotrack localize SOURCE --realtime`: poses of the processed frames, TUM timestamps =
    capture times, frames numbered by capture index."""
    from autotrack.cli.reports import DEFAULT_FPS, summarise
    from autotrack.io.live import LiveLog, LiveReader, describe_source
    from autotrack.localization.pnp import boxes_by_landmark
    from autotrack.pipeline.live import run_live, warm_up
    from autotrack.pipeline.outcomes import OutcomeLog

    boxes = boxes_by_landmark(init, scene)
    reader = LiveReader(args.sequence, fps=args.fps)
    warm_up(tracker_params, reader.frame_size, list(boxes.values()), tracker)
    progress = tqdm(unit="frame", desc=describe_source(args.sequence), disable=args.quiet)
    records = OutcomeLog(scene.landmark_ids)
    with reader, progress:
        log = LiveLog(reader)
        outcomes = run_live(
            log,
            tracker_params,
            lambda pipeline, frame_index: pipeline.add_targets(frame_index, boxes),
            tracker=tracker,
            scene=scene,
            localizer_params=localizer_params,
            recording=session_recording(args, scene_path),
            fps=reader.fps or DEFAULT_FPS,
            threads=args.threads,
            tracker_processes=args.processes,
            map_window=0,  # the report needs boxes and poses only: memory stays flat
            **_pose_options(args),
        )
        for _, outcome in outcomes:
            records.append(outcome)
            progress.update()
    summary = log.summary()
    capture_times = np.array([frame.capture_time for frame in summary.processed])
    name = describe_source(args.sequence)
    print(summarise(records, capture_times, scene, args.out, args.tracks, None, name))
    if gt is not None:
        # The ground truth is timed by the source's frames: match by capture index / fps.
        source_fps = reader.source_fps or reader.fps or DEFAULT_FPS
        frame_times = records.frame_indices / source_fps
        table = summarise(records, frame_times, scene, None, None, gt, name)
        print(table.split("\n", 1)[1])
    if args.session is not None:
        print(f"session recorded to {args.session}")
    _finish(summary, args.frame_log)
    return 0
