"""`autotrack localize` (camera trajectory from four tracked landmarks) and `autotrack synth`
(the synthetic test bed)."""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm import tqdm

from autotrack.errors import BoxError, InputError
from autotrack.params import PRESETS, TrackerParams, preset
from autotrack.scene import Scene, load_scene, scene_warnings

if TYPE_CHECKING:
    from autotrack.sessions import SessionRecorder

DEFAULT_FPS = 10.0
LARGE_ERROR_CM = 20.0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    _add_localize(subparsers)
    _add_synth(subparsers)


# ---------------------------------------------------------------------------------------------
# autotrack localize


def _add_localize(subparsers: argparse._SubParsersAction) -> None:
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
    parser.add_argument("sequence", type=Path, help="folder of images, video, or sequence folder")
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
    parser.add_argument("--preset", default="autotrack", choices=sorted(PRESETS))
    parser.add_argument(
        "--threads",
        type=int,
        default=2,
        help="track the landmarks on this many threads (default 2: 28.8 fps instead of 22.4 "
        "for four targets at 1280x720 on a 2-core machine)",
    )
    parser.add_argument(
        "--max-rms",
        type=float,
        default=None,
        metavar="PX",
        help="largest RMS reprojection error of a trusted pose (pixels, default 3)",
    )
    parser.add_argument(
        "--session",
        type=Path,
        default=None,
        metavar="FILE",
        help="record the run to this new MCAP session file (never overwritten; see "
        "`autotrack session`)",
    )
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
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(func=run_localize)


def read_init_boxes(path: Path) -> dict[str, tuple[float, float, float, float]] | list:
    """boxes.json: {landmark id: [x, y, w, h]} (0-based pixels), or a list of boxes."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as error:
        raise InputError(f"cannot read boxes file {path}: {error.strerror or error}") from None
    except json.JSONDecodeError as error:
        raise InputError(f"boxes file {path} is not valid JSON (line {error.lineno})") from None

    def box(value: Any, where: str) -> tuple[float, float, float, float]:
        if (
            not isinstance(value, list)
            or len(value) != 4
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
        ):
            raise BoxError(f"{path}: {where} must be [x, y, w, h] (four numbers, 0-based pixels)")
        x, y, w, h = (float(v) for v in value)
        if w <= 0 or h <= 0 or not all(math.isfinite(v) for v in (x, y, w, h)):
            raise BoxError(f"{path}: {where} needs a positive width and height")
        return (x, y, w, h)

    if isinstance(data, dict):
        return {str(k): box(v, f"the box of {k!r}") for k, v in data.items()}
    if isinstance(data, list):
        return [box(v, f"box {i + 1}") for i, v in enumerate(data)]
    raise InputError(f"{path}: expected {{landmark id: [x, y, w, h]}} or a list of boxes")


def _default_file(given: Path | None, sequence: Path, name: str, option: str) -> Path:
    if given is not None:
        return given
    candidate = sequence / name
    if sequence.is_dir() and candidate.is_file():
        return candidate
    raise InputError(f"give {option} (no {name} in {sequence})")


def run_localize(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from autotrack.frames import open_frames
    from autotrack.localize import LocalizerParams, localize_sequence
    from autotrack.reacquire import ReacquireParams
    from autotrack.refine import RefineParams
    from autotrack.smoothing import SmootherParams

    scene_path = _default_file(args.scene, args.sequence, "scene.json", "--scene")
    scene = load_scene(scene_path)
    for warning in scene_warnings(scene):
        print(f"autotrack: warning: {warning}", file=sys.stderr)
    init = read_init_boxes(_default_file(args.init, args.sequence, "boxes.json", "--init"))
    if args.threads < 1:
        raise InputError("--threads must be at least 1")
    localizer_params = LocalizerParams()
    if args.max_rms is not None:
        if args.max_rms <= 0:
            raise InputError("--max-rms must be positive")
        localizer_params = replace(localizer_params, max_rms_error_px=args.max_rms)
    gt = None
    if args.gt is not None:
        from autotrack.localize import read_tum

        gt = read_tum(args.gt)
    if args.no_reacquire is False and args.no_refine:
        raise InputError("re-acquisition needs the refiner's templates: add --no-reacquire")
    if args.smooth_lag < 0:
        raise InputError("--smooth-lag must be 0 or more")
    frames = open_frames(args.sequence)
    fps = args.fps or frames.fps or DEFAULT_FPS
    if fps <= 0:
        raise InputError("--fps must be positive")
    smoother = SmootherParams(fps=fps, lag_frames=args.smooth_lag) if args.smoothed else None
    records = []
    tracker_params = preset(args.preset)
    recorder = _open_recorder(args.session, args.sequence, tracker_params, scene_path, fps)
    progress = tqdm(total=len(frames), unit="frame", desc=frames.name, disable=args.quiet)
    with frames, progress, recorder or contextlib.nullcontext():
        pipeline = localize_sequence(
            frames,
            scene,
            init,
            tracker_params,
            localizer_params,
            assignment_known=isinstance(init, dict),
            threads=args.threads,
            refine_params=None if args.no_refine else RefineParams(),
            reacquire_params=None if args.no_reacquire else ReacquireParams(),
        )
        for record in pipeline:
            records.append(record)
            if recorder is not None:
                _record_frame(recorder, record, scene)
            progress.update()
    timestamps = np.arange(len(records)) / fps
    report = summarise(
        records, timestamps, scene, args.out, args.tracks, gt, frames.name, args.smoothed, smoother
    )
    print(report)
    if args.session is not None:
        print(f"session recorded to {args.session}")
    return 0


def _open_recorder(
    session: Path | None,
    sequence: Path,
    tracker_params: TrackerParams,
    scene_path: Path,
    fps: float,
) -> SessionRecorder | None:
    """A SessionRecorder writing `session` (a new file), or None without --session."""
    if session is None:
        return None
    from autotrack.sessions import SessionRecorder

    return SessionRecorder(
        session,
        source=str(sequence),
        tracker_params=tracker_params,
        scene_path=scene_path,
        fps=fps,
    )


def _record_frame(recorder: SessionRecorder, record: Any, scene: Scene) -> None:
    """One frame of the pipeline into the session: landmarks and first boxes, tracks, pose."""
    if record.frame_index == 0:
        recorder.log_landmarks(scene)
        for landmark_id, track in record.tracks.items():
            recorder.log_event("box_drawn", 0, landmark_id, track.box)
    for landmark_id, track in record.tracks.items():
        recorder.log_target(landmark_id, track, landmark_id=landmark_id)
    recorder.log_pose(record.pose)


def summarise(
    records: Sequence[Any],
    timestamps: np.ndarray,
    scene: Scene,
    out: Path | None,
    tracks: Path | None,
    gt: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
    name: str,
    smoothed_out: Path | None = None,
    smoother: Any = None,
) -> str:
    """Write the requested files and return the text report (`name` labels the Table-3 row).

    With `smoothed_out` and `smoother` (SmootherParams) the smoothed trajectory is written there
    too and gets its own Table-3 row."""
    from autotrack.localize import format_table3, trajectory_errors, write_tum

    positions = np.array([r.pose.position for r in records]).reshape(-1, 3)
    quaternions = np.array([r.pose.quaternion_xyzw() for r in records]).reshape(-1, 4)
    valid = sum(r.pose.valid for r in records)
    three = sum(r.pose.valid and len(r.pose.used_landmarks) == 3 for r in records)
    lines = [
        f"frames: {len(records)}  valid poses: {valid} ({three} from three landmarks)  "
        f"invalid: {len(records) - valid}"
    ]
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        written = write_tum(out, timestamps, positions, quaternions)
        lines.append(f"poses written to {out} ({written} rows, TUM camera-to-world)")
    if tracks is not None:
        tracks.parent.mkdir(parents=True, exist_ok=True)
        write_tracks_csv(tracks, records, timestamps, scene)
        lines.append(f"per-frame tracks written to {tracks}")
    smoothed_positions = None
    if smoothed_out is not None and smoother is not None:
        from autotrack.smoothing import samples_from_poses, smooth_poses

        samples = list(smooth_poses(samples_from_poses([r.pose for r in records]), smoother))
        smoothed_positions = np.array([p.position for p in samples]).reshape(-1, 3)
        smoothed_out.parent.mkdir(parents=True, exist_ok=True)
        written = write_tum(
            smoothed_out,
            timestamps,
            smoothed_positions,
            np.array([p.quaternion_xyzw for p in samples]).reshape(-1, 4),
        )
        lines.append(
            f"smoothed poses written to {smoothed_out} ({written} rows, latency "
            f"{smoother.lag_frames} frames = {smoother.latency_s:.2f} s)"
        )
    if gt is not None:
        gt_times, gt_positions, _ = gt
        errors = trajectory_errors(timestamps, positions, gt_times, gt_positions)
        lines.append(format_table3([(name, errors)]))
        if smoothed_positions is not None:
            smoothed_errors = trajectory_errors(
                timestamps, smoothed_positions, gt_times, gt_positions
            )
            lines.append(
                f"smoothed: RMSE {smoothed_errors.rmse_cm:.2f} cm, max "
                f"{smoothed_errors.max_error_cm:.2f} cm over {smoothed_errors.frames} frames"
            )
        large = int(np.sum(errors.errors_cm > LARGE_ERROR_CM))
        lines.append(f"valid frames more than {LARGE_ERROR_CM:g} cm off: {large}")
    return "\n".join(lines)


def write_tracks_csv(
    path: Path, records: Sequence[Any], timestamps: np.ndarray, scene: Scene
) -> None:
    """One row per frame: pose (NaN when invalid), validity, landmarks used and left out (why),
    reason when invalid, and per landmark its box, peak score, aberrance flag and reprojection
    error; then per landmark the point given to the solver and whether it was refined, and the
    frame's landmark events (out of view, re-acquired)."""
    ids = scene.landmark_ids
    header = ["frame", "timestamp", "valid", "tx", "ty", "tz", "qx", "qy", "qz", "qw"]
    header += ["rms_px", "position_std_m", "used", "excluded", "reason"]
    for landmark_id in ids:
        header += [
            f"{landmark_id}_{k}" for k in ("x", "y", "w", "h", "peak", "aberrant", "error_px")
        ]
    # The point given to the solver (refined or box centre) and what happened to the landmark.
    for landmark_id in ids:
        header += [f"{landmark_id}_{k}" for k in ("u", "v", "refined")]
    header.append("events")
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for record, stamp in zip(records, timestamps, strict=True):
            pose = record.pose
            row: list[Any] = [record.frame_index, f"{stamp:.6f}", int(pose.valid)]
            row += [f"{v:.6f}" for v in pose.position]
            row += [f"{v:.6f}" for v in pose.quaternion_xyzw()]
            row += [f"{pose.rms_error_px:.3f}", f"{pose.position_std_m:.4f}"]
            excluded = "; ".join(f"{k} {why}" for k, why in pose.excluded_landmarks.items())
            row += [" ".join(pose.used_landmarks), excluded, pose.reason]
            for landmark_id in ids:
                track = record.tracks.get(landmark_id)
                if track is None:
                    row += ["nan"] * 6
                else:
                    row += [f"{v:.2f}" for v in track.box]
                    row += [f"{track.peak_score:.4f}", int(track.aberrant)]
                row.append(f"{pose.reprojection_errors.get(landmark_id, math.nan):.3f}")
            for landmark_id in ids:
                u, v = record.image_points.get(landmark_id, (math.nan, math.nan))
                row += [f"{u:.3f}", f"{v:.3f}", int(record.refined.get(landmark_id, False))]
            row.append("; ".join(f"{k} {what}" for k, what in record.events.items()))
            writer.writerow(row)


# ---------------------------------------------------------------------------------------------
# autotrack synth


def _add_synth(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "synth",
        help="render the synthetic localisation test bed (sequences with exact ground truth)",
        description=(
            "Render synthetic indoor sequences like the paper's localisation experiment: four "
            "landmarks, a moving 1280x720 camera at 10 fps, lighting changes, noise and motion "
            "blur, with exact camera poses, intrinsics and landmark boxes. Each sequence gets a "
            "folder OUT_DIR/<name>/ with img/, scene.json, boxes.json, poses_gt.tum, "
            "groundtruth/<landmark>.txt and sequence.json."
        ),
    )
    parser.add_argument("out_dir", type=Path, help="folder to write the sequences into")
    parser.add_argument("--sequences", type=int, default=6, help="how many (default 6)")
    parser.add_argument(
        "--frames",
        type=int,
        default=None,
        help="frames per sequence (default: the paper's 652, 431, 400, 381, 352, 450)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of everything random")
    parser.add_argument(
        "--width", type=int, default=1280, help="image width, 16:9 (default 1280, as the paper)"
    )
    parser.add_argument("--jpeg-quality", type=int, default=90, help="JPEG quality (default 90)")
    parser.add_argument(
        "--demo",
        action="store_true",
        help=(
            "write the app's embedded demo instead: one short sequence straight into OUT_DIR "
            "(60 frames, 960x540, JPEG quality 60)"
        ),
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(func=run_synth)


def run_synth(args: argparse.Namespace) -> int:
    from autotrack.synthetic import (
        RenderSettings,
        generate_demo,
        generate_test_bed,
        sequence_specs,
    )

    if args.width < 64 or args.width % 16:
        raise InputError("--width must be a multiple of 16, at least 64 (16:9 images)")
    if not 1 <= args.jpeg_quality <= 100:
        raise InputError("--jpeg-quality must be between 1 and 100")
    if args.demo:
        spec = generate_demo(args.out_dir, seed=args.seed)
        print(f"demo written to {args.out_dir} ({spec.frames} frames, {spec.trajectory})")
        return 0
    settings = RenderSettings(
        width=args.width, height=args.width * 9 // 16, jpeg_quality=args.jpeg_quality
    )
    specs = sequence_specs(args.sequences, args.frames, args.seed, settings)
    total = sum(spec.frames for spec in specs)
    with tqdm(total=total, unit="frame", desc="rendering", disable=args.quiet) as progress:
        folders = generate_test_bed(args.out_dir, specs, progress.update)
    for folder, spec in zip(folders, specs, strict=True):
        print(f"{folder}  {spec.trajectory}  {spec.frames} frames")
    return 0
