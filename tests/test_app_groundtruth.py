"""The ground truth a sequence carries, used by the app: the demo's per-landmark boxes for the
Ground truth tab's scores (the library's metrics), and its poses_gt.tum for the camera's
position and rotation error (ATE, RPE per second), without a browser."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from autotrack.evaluation.metrics import score_sequence
from autotrack.io.tum import read_tum
from autotrack.localization.trajectory import trajectory_errors
from autotrack.result import PoseEstimate
from autotrack_studio.groundtruth import TruthPoses, load_truth_poses, pose_errors
from autotrack_studio.truth_commands import truth_views
from autotrack_studio.truthplots import pose_error_text, scores_text
from autotrack_studio.view3d import view3d_legend
from tests.test_app_controller import DEMO, _controller


def _pose(index: int, rotation: np.ndarray, position: np.ndarray) -> PoseEstimate:
    return PoseEstimate(index, True, rotation, np.asarray(position, float), {}, ())


def test_the_demo_scores_each_landmarks_target_against_its_ground_truth(tmp_path: Path) -> None:
    controller = _controller(tmp_path / "sessions")
    controller.open_initial()
    try:
        assert set(controller.landmark_truth) == set(controller.run.scene.landmark_ids)
        assert controller.has_truth and controller.truth is None
        assert all(view.frames is None for view in truth_views(controller))  # no target yet
        controller.seek(2)
        controller.start_from_truth()  # one target per landmark, from its box on frame 3
        run = controller.run
        assert len(run.targets) == 4 and controller.cursor == 2
        controller.seek(9)
        views = truth_views(controller)
        assert [view.label for view in views] == [f"GT {lid}" for lid in run.scene.landmark_ids]
        for view in views:  # the library's metrics on the frames the target tracked
            target = next(t for t in run.targets.values() if t.id == view.target_id)
            truth = np.loadtxt(DEMO / "groundtruth" / f"{target.landmark_id}.txt", delimiter=",")
            boxes = np.array([target.results[k].box for k in range(2, 10)])
            expected = score_sequence(target.id, boxes, truth[2:10])
            assert view.frames == (2, 9) and view.box == pytest.approx(tuple(truth[9]))
            assert view.precision == expected.precision and view.auc == expected.auc
            # Started from the ground truth: its first box is the truth on the pixel grid.
            assert target.results[2].box == pytest.approx(tuple(truth[2]), abs=2.0)  # its grid
        text = scores_text(controller.snapshot().truth, views)
        assert text.count("| GT ") == 4 and "P@20" in text
        controller.start_from_truth()  # again: the same four targets restart there
        assert len(controller.run.targets) == 4
    finally:
        controller.close()


def test_the_demo_pose_error_is_the_librarys_ate(tmp_path: Path) -> None:
    controller = _controller(tmp_path / "sessions")
    controller.open_initial()
    try:
        controller.load_boxes_json()
        controller.seek(12)
        run, truth = controller.run, controller.truth_poses
        assert truth is not None and np.isfinite(truth.positions).all()
        fps = run.fps or 10.0  # the demo's images carry no rate; the display assumes 10
        errors = pose_errors(truth, run.poses, fps)
        valid = sorted(index for index, pose in run.poses.items() if pose.valid)
        assert errors.frames == len(valid) >= 10
        stamps, gt_positions, _ = read_tum(DEMO / "poses_gt.tum")
        library = trajectory_errors(
            np.array(valid) / fps,
            np.array([run.poses[index].position for index in valid]),
            stamps,
            gt_positions,
        )
        assert errors.ate_m == pytest.approx(library.rmse_cm / 100.0, rel=1e-9)
        assert np.isfinite(errors.rpe_m) and np.isfinite(errors.ate_deg)
        assert "ATE" in pose_error_text(errors) and "ATE" in view3d_legend(True, errors)
        assert "ground truth" in view3d_legend(True, errors)
    finally:
        controller.close()


def test_ate_and_rpe_per_second_on_known_errors() -> None:
    frames, fps = 40, 10.0
    truth_positions = np.stack([np.arange(frames) * 0.1, np.zeros(frames), np.ones(frames)], 1)
    turn = Rotation.from_euler("z", np.arange(frames)[:, None] * 3.0, degrees=True).as_matrix()
    truth = TruthPoses(truth_positions, turn)
    # A constant world offset: every position 5 cm off, every motion exact.
    offset = {k: _pose(k, turn[k], truth_positions[k] + [0.0, 0.05, 0.0]) for k in range(frames)}
    errors = pose_errors(truth, offset, fps)
    assert errors.ate_m == pytest.approx(0.05) and errors.rpe_m == pytest.approx(0.0, abs=1e-12)
    assert errors.ate_deg == pytest.approx(0.0, abs=1e-6)
    # A drift of 1 cm a frame along world x: 10 cm over each second, the ATE its RMS.
    drift = {k: _pose(k, turn[k], truth_positions[k] + [0.01 * k, 0.0, 0.0]) for k in range(frames)}
    errors = pose_errors(truth, drift, fps)
    assert errors.rpe_m == pytest.approx(0.1)
    assert errors.ate_m == pytest.approx(math.sqrt(np.mean((0.01 * np.arange(frames)) ** 2)))
    # Every camera turned 2 degrees more about z (as the flight turns): ATE 2 deg, RPE 0.
    tilt = Rotation.from_euler("z", 2.0, degrees=True).as_matrix()
    turned = {k: _pose(k, turn[k] @ tilt, truth_positions[k]) for k in range(frames)}
    errors = pose_errors(truth, turned, fps)
    assert errors.ate_deg == pytest.approx(2.0) and errors.rpe_deg == pytest.approx(0.0, abs=1e-5)
    # Untrusted and missing poses are left out, not counted as zero error.
    del drift[3]
    drift[4] = PoseEstimate(4, False, np.full((3, 3), np.nan), np.full(3, np.nan), {}, ())
    assert pose_errors(truth, drift, fps).frames == frames - 2


def test_ground_truth_poses_are_matched_to_frames_by_timestamp(tmp_path: Path) -> None:
    (tmp_path / "scene.json").write_text("{}")
    rows = ["# t x y z qx qy qz qw", "0.0 1 0 0 0 0 0 1", "0.2 3 0 0 0 0 0 1"]
    (tmp_path / "poses_gt.tum").write_text("\n".join(rows) + "\n")
    poses = load_truth_poses(tmp_path / "scene.json", 4, 10.0)
    np.testing.assert_array_equal(poses.positions[:, 0], [1.0, np.nan, 3.0, np.nan])
    np.testing.assert_allclose(poses.rotations[0], np.eye(3))
    assert load_truth_poses(None, 4, 10.0) is None
