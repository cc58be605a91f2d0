"""`--realtime` for `autotrack track` and `autotrack localize`: the live reader in the commands.

Not a command of its own: `track` and `localize` add these options and hand over to
`run_track_live` / `run_localize_live` when `--realtime` is given.
"""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from autotrack.errors import InputError


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
    """Refuse camera indices and streams without --realtime, and --frame-log without it."""
    from autotrack.live import describe_source, is_live_only

    if not args.realtime and is_live_only(args.sequence):
        raise InputError(f"{describe_source(args.sequence)} is live input: add --realtime")
    if not args.realtime and args.frame_log is not None:
        raise InputError("--frame-log records live runs: add --realtime")


def _finish(summary: Any, frame_log: Path | None) -> None:
    from autotrack.live import write_frame_log

    print(summary.describe())
    if frame_log is not None:
        frame_log.parent.mkdir(parents=True, exist_ok=True)
        write_frame_log(frame_log, summary)
        print(f"frame log written to {frame_log}")


def run_track_live(args: argparse.Namespace, params: Any, init_box: np.ndarray | None) -> int:
    """`autotrack track SOURCE --realtime`: boxes of the processed frames, NaN rows for the
    dropped ones, and the drop/latency report."""
    from autotrack.datasets import write_boxes
    from autotrack.live import LiveReader, describe_source, track_live, warm_up
    from autotrack.tracker import AutoTrack

    if init_box is None:
        raise InputError("live input has no ground truth: give the initial box with --init x,y,w,h")
    tracker = AutoTrack(params)
    reader = LiveReader(args.sequence, fps=args.fps)
    warm_up(params, reader.frame_size, [init_box])
    progress = tqdm(unit="frame", desc=describe_source(args.sequence), disable=args.quiet)
    with reader, progress:
        boxes, summary = track_live(
            reader, tracker, init_box, on_result=lambda frame, result: progress.update()
        )
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_boxes(args.out, boxes)
        print(f"boxes written to {args.out} (one row per captured frame, NaN where dropped)")
    _finish(summary, args.frame_log)
    return 0


def _open_live_recorder(
    args: argparse.Namespace, tracker_params: Any, scene_path: Path, fps: float
) -> Any:
    """The --session recorder of a live run: the processed frames are embedded (JPEG), since a
    live source cannot be replayed."""
    if args.session is None:
        return None
    from autotrack.sessions import SessionRecorder

    return SessionRecorder(
        args.session,
        source=str(args.sequence),
        tracker_params=tracker_params,
        scene_path=scene_path,
        fps=fps,
        embed_frames=True,
    )


def run_localize_live(
    args: argparse.Namespace,
    *,
    scene: Any,
    scene_path: Path,
    init: Any,
    tracker_params: Any,
    localizer_params: Any,
    gt: Any,
) -> int:
    """`autotrack localize SOURCE --realtime`: poses of the processed frames, TUM timestamps =
    capture times, frames numbered by capture index."""
    from autotrack.cli.localize import DEFAULT_FPS, _record_frame, summarise
    from autotrack.live import LiveLog, LiveReader, describe_source, warm_up, with_capture_index
    from autotrack.localize import localize_sequence

    records = []
    reader = LiveReader(args.sequence, fps=args.fps)
    warm_up(
        tracker_params, reader.frame_size, list(init.values() if isinstance(init, dict) else init)
    )
    progress = tqdm(unit="frame", desc=describe_source(args.sequence), disable=args.quiet)
    with reader, progress:
        fps = reader.fps or DEFAULT_FPS
        recorder = _open_live_recorder(args, tracker_params, scene_path, fps)
        log = LiveLog(reader)
        with recorder or contextlib.nullcontext():
            pipeline = localize_sequence(
                log.images(),
                scene,
                init,
                tracker_params,
                localizer_params,
                assignment_known=isinstance(init, dict),
                threads=args.threads,
            )
            for record in pipeline:
                frame = log.result_ready()
                record = with_capture_index(record, frame.index)
                records.append(record)
                if recorder is not None:
                    recorder.log_frame(frame.index, frame.image)
                    _record_frame(recorder, record, scene)
                progress.update()
    summary = log.summary()
    capture_times = np.array([frame.capture_time for frame in summary.processed])
    name = describe_source(args.sequence)
    print(summarise(records, capture_times, scene, args.out, args.tracks, None, name))
    if gt is not None:
        # The ground truth is timed by the source's frames: match by capture index / fps.
        source_fps = reader.source_fps or fps
        frame_times = np.array([record.frame_index for record in records]) / source_fps
        table = summarise(records, frame_times, scene, None, None, gt, name)
        print(table.split("\n", 1)[1])
    if args.session is not None:
        print(f"session recorded to {args.session}")
    _finish(summary, args.frame_log)
    return 0
