"""`autotrack localize`: the camera trajectory from four tracked landmarks, over the pipeline."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from autotrack.cli.checks import (
    add_session_arguments,
    add_tracker_argument,
    check_output_file,
    check_session_file,
    chosen_tracker,
    finite,
    session_recording,
)
from autotrack.cli.live import add_live_arguments, check_source, run_localize_live
from autotrack.cli.reports import DEFAULT_FPS, smoothed_report, summarise
from autotrack.cli.timing import StartupClock
from autotrack.errors import InputError
from autotrack.io.boxes_json import read_boxes_json
from autotrack.io.live import source_argument
from autotrack.localization.scene import load_scene, scene_warnings


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "localize",
        help="camera trajectory from four tracked landmarks of known position",
        description=(
            "Track the scene's landmarks through SEQUENCE with AutoTrack and solve the camera "
            "pose per frame (paper section 4). Poses are written in the TUM format "
            "(timestamp tx ty tz qx qy qz qw, camera-to-world, metres); frames without a "
            "trusted pose are left out of it and marked valid=0 in --tracks. "
            "See docs/localization.md."
        ),
    )
    parser.add_argument(
        "sequence",
        type=source_argument,
        help="folder of images, video, or sequence folder; with --realtime a camera index, "
        "stream URL or video",
    )
    parser.add_argument(
        "--scene",
        type=Path,
        default=None,
        help="scene JSON: camera intrinsics and landmarks (default: SEQUENCE/scene.json)",
    )
    parser.add_argument(
        "--init",
        type=Path,
        default=None,
        help=(
            "frame-1 boxes as JSON {landmark id: [x, y, w, h]} in 0-based pixels, or a list of "
            "boxes to let the correspondence search assign them (default: SEQUENCE/boxes.json)"
        ),
    )
    parser.add_argument("--out", type=Path, default=None, help="write the poses (TUM) here")
    parser.add_argument(
        "--tracks", type=Path, default=None, help="write per-frame boxes, errors and poses (CSV)"
    )
    parser.add_argument(
        "--gt", type=Path, default=None, help="ground-truth TUM poses: print Table-3 errors"
    )
    parser.add_argument(
        "--fps",
        type=float,
        default=None,
        help=f"frame rate for timestamps (default: the video's, else {DEFAULT_FPS:g})",
    )
    add_tracker_argument(parser)
    _add_concurrency_arguments(parser)
    parser.add_argument(
        "--max-rms",
        type=float,
        default=None,
        metavar="PX",
        help="largest RMS reprojection error of a trusted pose (pixels, default 3)",
    )
    add_session_arguments(parser)
    parser.add_argument(
        "--force", action="store_true", help="replace existing --out and --tracks files"
    )
    _add_pose_arguments(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_live_arguments(parser)
    parser.set_defaults(func=run_localize)


def _add_concurrency_arguments(parser: argparse.ArgumentParser) -> None:
    """--threads, --processes."""
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="track the landmarks on this many threads (default 1 with several processes, "
        "else 2; docs/benchmarks.md has the frame rates)",
    )
    parser.add_argument(
        "--processes",
        type=int,
        default=None,
        help="spread the landmarks over this many processes (this one and N-1 children: "
        "parallel where threads share Python's lock; default 2 for two landmarks or more on "
        "two cores or more, else 1; see docs/benchmarks.md, Speed)",
    )


def _add_pose_arguments(parser: argparse.ArgumentParser) -> None:
    """--no-refine, --no-reacquire, --smoothed, --smooth-lag."""
    parser.add_argument(
        "--no-refine",
        action="store_true",
        help="use the trackers' box centres as image points (no sub-pixel template alignment)",
    )
    parser.add_argument(
        "--no-reacquire",
        action="store_true",
        help="do not gate landmarks the pose puts out of view nor restart lost ones where the "
        "pose predicts them",
    )
    parser.add_argument(
        "--smoothed",
        type=Path,
        default=None,
        metavar="FILE",
        help="also write the smoothed trajectory (constant-velocity Kalman + fixed-lag RTS) "
        "here (TUM); --out keeps the raw per-frame poses",
    )
    parser.add_argument(
        "--smooth-lag",
        type=int,
        default=3,
        metavar="N",
        help="smoother lag in frames: the smoothed pose of a frame uses N later frames, a "
        "latency of N / fps seconds (default 3; 0 = causal Kalman filter)",
    )


def _default_file(given: Path | None, sequence: Path | str, name: str, option: str) -> Path:
    if given is not None:
        return given
    candidate = Path(sequence) / name
    if Path(sequence).is_dir() and candidate.is_file():
        return candidate
    raise InputError(f"give {option} (no {name} in {sequence})")


def _check_arguments(args: argparse.Namespace) -> None:
    """Outputs writable and not clobbered, numbers in range: before any work starts."""
    for path, option in (
        (args.out, "--out"),
        (args.tracks, "--tracks"),
        (args.smoothed, "--smoothed"),
    ):
        check_output_file(path, option, force=args.force)
    check_session_file(args.session)
    finite(args.fps, "--fps", low=0)
    finite(args.max_rms, "--max-rms", low=0)
    if args.threads is not None and args.threads < 1:
        raise InputError("--threads must be at least 1")
    if args.processes is not None and args.processes < 1:
        raise InputError("--processes must be at least 1")
    if not args.no_reacquire and args.no_refine:
        raise InputError("re-acquisition needs the refiner's templates: add --no-reacquire")
    if args.smooth_lag < 0:
        raise InputError("--smooth-lag must be 0 or more")


def _choose_concurrency(args: argparse.Namespace, target_count: int) -> None:
    """--threads and --processes where not given (`chosen_concurrency`)."""
    from autotrack.tracker.parallel.multi import chosen_concurrency

    args.threads, args.processes = chosen_concurrency(args.threads, args.processes, target_count)


def run_localize(args: argparse.Namespace) -> int:
    clock = StartupClock()
    from autotrack.io.frames import open_frames
    from autotrack.io.tum import read_tum
    from autotrack.localization.localizer import LocalizerParams
    from autotrack.localization.reacquire import ReacquireParams
    from autotrack.localization.refine import RefineParams
    from autotrack.localization.smoothing import SmootherParams
    from autotrack.pipeline import localize_sequence
    from autotrack.pipeline.outcomes import OutcomeLog

    _check_arguments(args)
    scene_path = _default_file(args.scene, args.sequence, "scene.json", "--scene")
    scene = load_scene(scene_path)
    for warning in scene_warnings(scene):
        print(f"autotrack: warning: {warning}", file=sys.stderr)
    init = read_boxes_json(_default_file(args.init, args.sequence, "boxes.json", "--init"))
    _choose_concurrency(args, len(init))
    localizer_params = LocalizerParams()
    if args.max_rms is not None:
        localizer_params = replace(localizer_params, max_rms_error_px=args.max_rms)
    gt = None if args.gt is None else read_tum(args.gt)
    check_source(args)
    tracker, tracker_params = chosen_tracker(args)
    if args.realtime:
        return run_localize_live(
            args,
            scene=scene,
            scene_path=scene_path,
            init=init,
            tracker=tracker,
            tracker_params=tracker_params,
            localizer_params=localizer_params,
            gt=gt,
        )
    frames = open_frames(args.sequence)
    fps = args.fps or frames.fps or DEFAULT_FPS
    if fps <= 0:
        raise InputError("--fps must be positive")
    smoother = SmootherParams(fps=fps, lag_frames=args.smooth_lag) if args.smoothed else None
    recording = session_recording(args, scene_path)
    records = OutcomeLog(scene.landmark_ids)
    progress = tqdm(total=len(frames), unit="frame", desc=frames.name, disable=args.quiet)
    with frames, progress:
        outcomes = localize_sequence(
            frames,
            scene,
            init,
            tracker_params,
            localizer_params,
            tracker=tracker,
            recording=recording,
            fps=fps,
            threads=args.threads,
            processes=args.processes,
            refine_params=None if args.no_refine else RefineParams(),
            reacquire_params=None if args.no_reacquire else ReacquireParams(),
            map_window=0,  # the report needs boxes and poses only: memory stays flat
        )
        for outcome in outcomes:
            records.append(outcome)
            progress.update()
            clock.tick()
    timestamps = np.arange(len(records)) / fps
    report = summarise(records, timestamps, scene, args.out, args.tracks, gt, frames.name)
    report += "\n" + clock.report("localising (decoding, tracking, poses)")
    if args.smoothed is not None and smoother is not None:
        report += "\n" + smoothed_report(records, timestamps, args.smoothed, smoother, gt)
    print(report)
    if not any(pose.valid for pose in records.poses):
        print(
            "autotrack: warning: no frame got a valid pose: check the scene's intrinsics and "
            "landmarks, the boxes and --max-rms",
            file=sys.stderr,
        )
    if args.session is not None:
        print(f"session recorded to {args.session}")
    return 0
