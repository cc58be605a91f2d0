"""Localisation on the synthetic test bed: raw, refined and smoothed poses vs the ground-truth-box
floor, on the six trajectories (paper Table 3) and the hard cases.

    python benchmarks/localization_table.py [FOLDER] [--frames N] [--seed S] [--jobs J]
                                            [--cases-only | --no-cases] [--case-frames N]

Generates the six sequences under FOLDER (default results/synthetic/) and the five hard cases
under FOLDER/cases/ (autotrack/scenarios.py: a passing board hides a landmark, a turn takes one
out of view, both, long-exposure bursts, a lighting step) unless they are already there. Each
sequence is tracked once, with sub-pixel refinement and re-acquisition on; from that one run:

  raw       poses from the trackers' box centres (no refinement);
  refined   poses from the refined points (autotrack/refine.py);
  smoothed  the refined poses through the fixed-lag smoother (autotrack/smoothing.py, 3 frames);
  GT boxes  poses from the ground-truth boxes' centres of the landmarks in view (the floor).

It prints per sequence the RMSE and largest error (cm), the valid and flagged (invalid) frames,
the frames more than 20 cm off that were NOT flagged, and for the hard cases how long after a
landmark came back into view it was used again with its point within 3 px of its true
projection. TUM files of every kind are written next to the frames (evo-readable).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from autotrack.io.frames import open_frames
from autotrack.io.tum import read_tum, write_tum
from autotrack.localization.camera import project_points
from autotrack.localization.localizer import Localizer, LocalizerParams
from autotrack.localization.pnp import box_centre
from autotrack.localization.reacquire import ReacquireParams
from autotrack.localization.refine import RefineParams
from autotrack.localization.scene import load_scene
from autotrack.localization.smoothing import SmootherParams, samples_from_poses, smooth_poses
from autotrack.localization.trajectory import TrajectoryErrors, format_table3, trajectory_errors
from autotrack.params import PRESETS, preset
from autotrack.pipeline import localize_sequence
from autotrack.synthetic.renderer import render_sequence
from autotrack.synthetic.scenarios import (
    BACK_FRACTION,
    ScenarioSpec,
    hidden_spans,
    read_visibility,
    render_scenario,
    scenario_specs,
)
from autotrack.synthetic.testbed import read_ground_truth_boxes, sequence_specs
from autotrack.synthetic.trajectories import RenderSettings, SequenceSpec

LARGE_ERROR_CM = 20.0
PAPER_RMSE_CM = 3.44
REACQUIRED_WITHIN_PX = 3.0
KINDS = ("GT boxes", "raw", "refined", "smoothed")


@dataclass(frozen=True)
class Row:
    """One kind of pose on one sequence."""

    errors: TrajectoryErrors
    valid: int
    flagged: int
    unflagged_large: int


@dataclass(frozen=True)
class SequenceResult:
    name: str
    rows: dict[str, Row]
    reacquired: list[tuple[str, int, int | None]] = field(default_factory=list)
    """(landmark, frame it came back in view, frames until used again; None = never)."""
    seconds: float = 0.0


def _matches(metadata: dict, trajectory: str, frames: int, seed: int, width: int) -> bool:
    return (
        metadata.get("trajectory") == trajectory
        and metadata.get("frames") == frames
        and metadata.get("seed") == seed
        and metadata.get("width") == width
    )


def ensure_sequence(folder: Path, spec: SequenceSpec | ScenarioSpec) -> Path:
    """Render the sequence (or hard case) unless an identical one is already there."""
    sequence = spec.sequence if isinstance(spec, ScenarioSpec) else spec
    target = folder / (spec.case if isinstance(spec, ScenarioSpec) else spec.name)
    metadata_path = target / "sequence.json"
    if metadata_path.is_file():
        metadata = json.loads(metadata_path.read_text())
        if (
            _matches(
                metadata,
                sequence.trajectory,
                sequence.frames,
                sequence.seed,
                sequence.settings.width,
            )
            and len(list((target / "img").glob("*.jpg"))) == sequence.frames
        ):
            return target
    if isinstance(spec, ScenarioSpec):
        return render_scenario(target, spec)
    return render_sequence(target, spec)


def _row(
    timestamps: np.ndarray,
    positions: np.ndarray,
    gt_times: np.ndarray,
    gt_positions: np.ndarray,
) -> Row:
    errors = trajectory_errors(timestamps, positions, gt_times, gt_positions)
    valid = int(np.sum(np.all(np.isfinite(positions), axis=1)))
    return Row(
        errors=errors,
        valid=valid,
        flagged=len(positions) - valid,
        unflagged_large=int(np.sum(errors.errors_cm > LARGE_ERROR_CM)),
    )


def evaluate(folder: Path, preset_name: str) -> SequenceResult:
    """One tracking run on a sequence and the four kinds of poses from it."""
    start = time.perf_counter()
    scene = load_scene(folder / "scene.json")
    boxes = json.loads((folder / "boxes.json").read_text())
    metadata = json.loads((folder / "sequence.json").read_text())
    fps = float(metadata["fps"])
    gt_times, gt_positions, gt_quaternions = read_tum(folder / "poses_gt.tum")
    truth = read_ground_truth_boxes(folder)
    visible = read_visibility(folder) if (folder / "visibility.csv").is_file() else None
    params = LocalizerParams()
    ids = scene.landmark_ids

    with open_frames(folder) as frames:
        records = list(
            localize_sequence(
                frames,
                scene,
                boxes,
                preset(preset_name),
                params,
                refine_params=RefineParams(),
                reacquire_params=ReacquireParams(),
            )
        )
    count = len(records)
    timestamps = np.arange(count) / fps
    raw_localizer, floor_localizer = Localizer(scene, params), Localizer(scene, params)
    raw_poses, floor_poses = [], []
    for record in records:
        k = record.frame_index
        # The raw run sees the same out-of-view gating as the refined one.
        raw_points = {
            i: (p if np.all(np.isfinite(record.image_points[i])) else (math.nan, math.nan))
            for i, p in record.box_centres.items()
        }
        raw_poses.append(
            raw_localizer.estimate(
                k,
                raw_points,
                {i: t.peak_score for i, t in record.landmark_tracks.items()},
                {i: t.aberrant for i, t in record.landmark_tracks.items()},
            )
        )
        in_view = [i for i in ids if visible is None or visible[i][k] >= BACK_FRACTION]
        floor_poses.append(
            floor_localizer.estimate(k, {i: box_centre(truth[i][k]) for i in in_view})
        )
    refined_poses = [r.pose for r in records]
    smoothed = list(smooth_poses(samples_from_poses(refined_poses), SmootherParams(fps=fps)))
    kinds = {
        "GT boxes": floor_poses,
        "raw": raw_poses,
        "refined": refined_poses,
        "smoothed": smoothed,
    }
    rows = {}
    for kind, poses in kinds.items():
        positions = np.array([p.position for p in poses]).reshape(-1, 3)
        # PoseEstimate has a quaternion_xyzw() method, the smoother's PoseSample the array.
        quaternions = np.array(
            [q() if callable(q := p.quaternion_xyzw) else q for p in poses]
        ).reshape(-1, 4)
        write_tum(
            folder / f"poses_{kind.replace(' ', '').lower()}.tum",
            timestamps,
            positions,
            quaternions,
        )
        rows[kind] = _row(timestamps, positions, gt_times, gt_positions)

    reacquired = []
    if visible is not None:
        reacquired = _reacquisition_delays(records, scene, visible, gt_positions, gt_quaternions)
    return SequenceResult(folder.name, rows, reacquired, time.perf_counter() - start)


def _reacquisition_delays(
    records: list, scene, visible: dict, gt_positions: np.ndarray, gt_quaternions: np.ndarray
) -> list[tuple[str, int, int | None]]:
    """Per hidden span: (landmark, frame it is back in view, frames until it is used again with
    its point within REACQUIRED_WITHIN_PX of its true projection; None: never)."""
    count = len(records)
    rotations = _rotations(gt_quaternions)
    reacquired = []
    for landmark_id in scene.landmark_ids:
        for _, back in hidden_spans(visible[landmark_id]):
            if back >= count:
                continue
            delay = None
            for k in range(back, count):
                pose = records[k].pose
                if not pose.valid or landmark_id not in pose.used_landmarks:
                    continue
                expected = project_points(
                    scene.camera,
                    scene.object_points((landmark_id,)),
                    rotations[k],
                    gt_positions[k],
                )[0]
                point = records[k].image_points[landmark_id]
                if math.dist(point, expected) <= REACQUIRED_WITHIN_PX:
                    delay = k - back
                    break
            reacquired.append((landmark_id, back, delay))
    return reacquired


def _rotations(quaternions_xyzw: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(quaternions_xyzw).as_matrix()


def format_cases(results: list[SequenceResult]) -> str:
    """Per sequence and kind of pose: RMSE, max, valid, flagged, > 20 cm and not flagged."""
    header = (
        f"{'Sequence':<20}{'poses':<10}{'RMSE(cm)':>9}{'max(cm)':>9}{'valid':>7}{'flagged':>8}"
        f"{'>20cm':>7}"
    )
    lines = [header, "-" * len(header)]
    for result in results:
        for n, kind in enumerate(KINDS):
            row = result.rows[kind]
            lines.append(
                f"{result.name if n == 0 else '':<20}{kind:<10}{row.errors.rmse_cm:>9.2f}"
                f"{row.errors.max_error_cm:>9.2f}{row.valid:>7d}{row.flagged:>8d}"
                f"{row.unflagged_large:>7d}"
            )
    return "\n".join(lines)


def pooled(results: list[SequenceResult], kind: str) -> tuple[float, float]:
    """RMSE over all frames and largest error (cm) of one kind of pose."""
    errors = np.concatenate([r.rows[kind].errors.errors_cm for r in results])
    return float(np.sqrt(np.mean(errors**2))), float(errors.max())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, nargs="?", default=Path("results/synthetic"))
    parser.add_argument("--sequences", type=int, default=6)
    parser.add_argument("--frames", type=int, default=None, help="default: the paper's counts")
    parser.add_argument("--case-frames", type=int, default=250, help="frames per hard case")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--preset", default="autotrack", choices=sorted(PRESETS))
    parser.add_argument("--jobs", type=int, default=1, help="sequences processed in parallel")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--no-cases", action="store_true", help="only the six trajectories")
    group.add_argument("--cases-only", action="store_true", help="only the hard cases")
    args = parser.parse_args(argv)

    specs = (
        []
        if args.cases_only
        else sequence_specs(args.sequences, args.frames, args.seed, RenderSettings())
    )
    cases = [] if args.no_cases else scenario_specs(args.seed, args.case_frames)
    start = time.perf_counter()
    folders = [ensure_sequence(args.folder, spec) for spec in specs]
    case_folders = [ensure_sequence(args.folder / "cases", spec) for spec in cases]
    print(f"sequences ready in {time.perf_counter() - start:.0f} s under {args.folder}")
    everything = folders + case_folders
    if args.jobs > 1:
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            results = list(pool.map(evaluate, everything, [args.preset] * len(everything)))
    else:
        results = [evaluate(folder, args.preset) for folder in everything]
    six, hard = results[: len(folders)], results[len(folders) :]
    ok = True
    if six:
        print(f"\nLocalisation by tracking, refined + smoothed (AutoTrack preset '{args.preset}')")
        print(format_table3([(r.name, r.rows["smoothed"].errors) for r in six]))
        print("\nError floor (ground-truth boxes, no tracker)")
        print(format_table3([(r.name, r.rows["GT boxes"].errors) for r in six]))
    print("\nPer sequence: raw, refined and smoothed poses against the ground-truth-box floor")
    print(format_cases(results))
    if six:
        floor_rmse, _ = pooled(six, "GT boxes")
        print("\nSix trajectories, all frames:")
        for kind in KINDS:
            rmse, worst = pooled(six, kind)
            print(f"  {kind:<10} RMSE {rmse:5.2f} cm   max {worst:5.2f} cm")
        rmse, worst = pooled(six, "smoothed")
        bound = 1.5 * floor_rmse + 0.5
        passed = rmse <= bound and worst < 4.0
        ok &= passed
        print(
            f"  refined + smoothed RMSE {rmse:.2f} cm <= 1.5 x floor + 0.5 = {bound:.2f} cm and "
            f"max {worst:.2f} < 4 cm: {'yes' if passed else 'NO'} (paper: {PAPER_RMSE_CM} cm)"
        )
    large = sum(r.rows[k].unflagged_large for r in results for k in ("refined", "smoothed"))
    print(f"frames > {LARGE_ERROR_CM:g} cm off and not flagged (refined, smoothed): {large}")
    ok &= large == 0
    if hard:
        print(
            f"\nRe-acquisition (frames from back in view to used again within "
            f"{REACQUIRED_WITHIN_PX:g} px)"
        )
        for r in hard:
            for landmark_id, back, delay in r.reacquired:
                text = "never" if delay is None else f"{delay} frames"
                print(f"  {r.name:<20} {landmark_id} back at frame {back:3d}: {text}")
                ok &= delay is not None and delay <= 10
    print(f"\n({sum(r.seconds for r in results):.0f} s of processing)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
