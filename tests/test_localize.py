"""Pose from landmarks: exact recovery, correspondence search, lost and drifting landmarks,
validity checks, TUM files, Table-3 metrics and the tracking pipeline on a generated sequence."""

from __future__ import annotations

import csv
import itertools
import json
import math
import re
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from autotrack.cli import main
from autotrack.errors import InputError
from autotrack.io.frames import open_frames
from autotrack.io.tum import read_tum, write_tum
from autotrack.localization.camera import project_points, rotation_angle_deg
from autotrack.localization.localizer import Localizer, LocalizerParams
from autotrack.localization.pnp import search_correspondences
from autotrack.localization.scene import load_scene
from autotrack.localization.trajectory import associate, format_table3, trajectory_errors
from autotrack.params import preset
from autotrack.pipeline import localize_sequence
from autotrack.synthetic.renderer import render_sequence
from autotrack.synthetic.testbed import read_ground_truth_boxes
from autotrack.synthetic.trajectories import (
    TRAJECTORIES,
    RenderSettings,
    SequenceSpec,
    ground_truth_poses,
)
from autotrack.synthetic.world import default_camera, default_scene

CAMERA = default_camera(1280, 720, RenderSettings().distortion)
SCENE = default_scene(CAMERA)
IDS = SCENE.landmark_ids


def poses_along(trajectory: str, frames: int = 60, period_s: float | None = 40.0):
    """Ground-truth poses of the first `frames` frames (at 10 fps) of a `period_s` trajectory."""
    spec = SequenceSpec("t", trajectory, frames, seed=3, period_s=period_s)
    _, rotations, positions = ground_truth_poses(spec)
    return rotations, positions


def exact_points(rotation, position, scene=SCENE) -> dict[str, tuple[float, float]]:
    projected = project_points(scene.camera, scene.object_points(), rotation, position)
    return {
        i: (float(u), float(v)) for i, (u, v) in zip(scene.landmark_ids, projected, strict=True)
    }


def test_pose_from_exact_projections_recovers_ground_truth():
    for trajectory in TRAJECTORIES:
        localizer = Localizer(SCENE)
        rotations, positions = poses_along(trajectory, period_s=None)  # the whole trajectory
        for frame in range(0, 60, 7):
            pose = localizer.estimate(frame, exact_points(rotations[frame], positions[frame]))
            assert pose.valid, pose.reason
            assert np.linalg.norm(pose.position - positions[frame]) < 1e-3
            assert rotation_angle_deg(pose.rotation, rotations[frame]) < 0.01
            assert pose.used_landmarks == IDS
            assert max(pose.reprojection_errors.values()) < 1e-3


def test_quaternion_is_the_rotation_in_tum_order():
    rotations, positions = poses_along("climb_yaw")
    pose = Localizer(SCENE).estimate(0, exact_points(rotations[0], positions[0]))
    quaternion = pose.quaternion_xyzw()
    np.testing.assert_allclose(Rotation.from_quat(quaternion).as_matrix(), rotations[0], atol=1e-9)
    assert quaternion[3] >= 0


def test_correspondence_search_finds_the_assignment():
    rotations, positions = poses_along("figure_eight")
    for frame, permutation in zip((0, 20, 40), itertools.permutations(range(4)), strict=False):
        points = project_points(CAMERA, SCENE.object_points(), rotations[frame], positions[frame])
        shuffled = points[list(permutation)]
        assignment = search_correspondences(shuffled, SCENE)
        assert {IDS[permutation[row]]: row for row in range(4)} == assignment
    # Every one of the 24 orders at one pose.
    points = project_points(CAMERA, SCENE.object_points(), rotations[10], positions[10])
    for permutation in itertools.permutations(range(4)):
        assignment = search_correspondences(points[list(permutation)], SCENE)
        assert all(IDS[permutation[row]] == landmark for landmark, row in assignment.items())


def test_correspondence_search_rejects_points_no_pose_explains():
    points = np.array([[100.0, 100.0], [110.0, 100.0], [120.0, 100.0], [600.0, 650.0]])
    assert search_correspondences(points, SCENE) == {}


def test_lost_landmark_keeps_a_three_point_pose():
    rotations, positions = poses_along("lateral_sweep")
    localizer = Localizer(SCENE)
    assert localizer.estimate(0, exact_points(rotations[0], positions[0])).valid
    for frame in (1, 2, 3):
        points = exact_points(rotations[frame], positions[frame])
        del points["C"]
        pose = localizer.estimate(frame, points)
        assert pose.valid, pose.reason
        assert pose.used_landmarks == ("A", "B", "D")
        assert pose.excluded_landmarks == {"C": "lost"}
        assert math.isnan(pose.reprojection_errors["C"])
        assert np.linalg.norm(pose.position - positions[frame]) < 1e-3


def test_three_landmarks_without_a_previous_pose_is_an_explicit_invalid_frame():
    rotations, positions = poses_along("circle")
    points = exact_points(rotations[0], positions[0])
    points["B"] = (math.nan, math.nan)
    pose = Localizer(SCENE).estimate(0, points)
    assert not pose.valid
    assert "only three landmarks" in pose.reason
    assert np.all(np.isnan(pose.position)) and np.all(np.isnan(pose.rotation))


def test_two_landmarks_give_an_invalid_frame_not_a_crash():
    rotations, positions = poses_along("circle")
    localizer = Localizer(SCENE)
    localizer.estimate(0, exact_points(rotations[0], positions[0]))
    points = exact_points(rotations[1], positions[1])
    pose = localizer.estimate(1, {"A": points["A"], "D": points["D"]})
    assert not pose.valid
    assert "only 2 usable landmark(s)" in pose.reason and "B lost" in pose.reason
    assert Localizer(SCENE).estimate(2, {}).valid is False


def test_degenerate_image_points_give_an_invalid_frame():
    coincident = {landmark: (100.0, 100.0) for landmark in IDS}
    on_a_line = {landmark: (10.0 * k, 10.0 * k) for k, landmark in enumerate(IDS)}
    pose = Localizer(SCENE).estimate(0, coincident)
    assert not pose.valid and "degenerate image points" in pose.reason
    pose = Localizer(SCENE).estimate(0, on_a_line)
    assert not pose.valid and ("degenerate" in pose.reason or "ill-conditioned" in pose.reason)
    assert search_correspondences(np.full((4, 2), 100.0), SCENE) == {}


def test_drifting_landmark_is_dropped_when_a_previous_pose_says_which():
    rotations, positions = poses_along("approach_retreat")
    localizer = Localizer(SCENE)
    localizer.estimate(0, exact_points(rotations[0], positions[0]))
    points = exact_points(rotations[1], positions[1])
    points["D"] = (points["D"][0] + 40.0, points["D"][1] - 15.0)
    pose = localizer.estimate(1, points)
    assert pose.valid, pose.reason
    assert pose.used_landmarks == ("A", "B", "C")
    assert np.linalg.norm(pose.position - positions[1]) < 1e-3
    # The outlier's distance from where the trusted pose puts it: the injected 40, -15 px.
    assert (
        pose.excluded_landmarks["D"]
        == f"outlier: {math.hypot(40, 15):.1f} px from the others' pose"
    )
    # Without a previous pose the same frame cannot be trusted.
    fresh = Localizer(SCENE).estimate(1, points)
    assert not fresh.valid and "disagree" in fresh.reason


def test_low_peak_score_drops_the_landmark():
    rotations, positions = poses_along("circle")
    params = LocalizerParams(min_peak_score=0.2)
    localizer = Localizer(SCENE, params)
    localizer.estimate(0, exact_points(rotations[0], positions[0]))
    scores = {"A": 0.6, "B": 0.05, "C": 0.5, "D": math.nan}
    pose = localizer.estimate(1, exact_points(rotations[1], positions[1]), confidences=scores)
    assert pose.valid and pose.used_landmarks == ("A", "C", "D")


def test_collapsing_peak_score_drops_the_landmark():
    rotations, positions = poses_along("circle")
    localizer = Localizer(SCENE)
    steady = {landmark: 0.04 for landmark in IDS}
    for frame in range(8):
        pose = localizer.estimate(frame, exact_points(rotations[frame], positions[frame]), steady)
        assert pose.used_landmarks == IDS
    collapsed = {**steady, "C": 0.006}
    pose = localizer.estimate(8, exact_points(rotations[8], positions[8]), collapsed)
    assert pose.valid and pose.used_landmarks == ("A", "B", "D")
    assert pose.excluded_landmarks["C"] == "peak 0.006 < 0.3 x its median 0.04"
    # A moderate dip (blur, lighting) keeps the landmark.
    dipped = {**steady, "C": 0.02}
    pose = localizer.estimate(9, exact_points(rotations[9], positions[9]), dipped)
    assert pose.used_landmarks == IDS


def test_aberrant_landmark_is_down_weighted():
    rotations, positions = poses_along("figure_eight")
    points = exact_points(rotations[5], positions[5])
    points["A"] = (points["A"][0] + 3.0, points["A"][1] + 2.0)
    plain = Localizer(SCENE).estimate(5, points)
    weighted = Localizer(SCENE).estimate(5, points, aberrant={"A": True})
    assert plain.valid and weighted.valid
    plain_error = np.linalg.norm(plain.position - positions[5])
    weighted_error = np.linalg.norm(weighted.position - positions[5])
    assert weighted_error < 0.6 * plain_error
    dropped = Localizer(SCENE, LocalizerParams(aberrant_weight=0.0))
    assert "A aberrant" in dropped.estimate(5, points, aberrant={"A": True}).reason


def test_implausible_jump_is_invalid_until_the_prior_expires():
    rotations, positions = poses_along("circle")
    params = LocalizerParams(prior_max_age_frames=3)
    localizer = Localizer(SCENE, params)
    assert localizer.estimate(0, exact_points(rotations[0], positions[0])).valid
    far_position = positions[0] + np.array([1.5, -0.5, 0.4])
    far = exact_points(rotations[0], far_position)
    jumped = localizer.estimate(1, far)
    assert not jumped.valid and "jump of" in jumped.reason
    assert not localizer.estimate(3, far).valid
    # Four consistent landmarks re-initialise once the previous pose is too old to vouch.
    again = localizer.estimate(4, far)
    assert again.valid and np.linalg.norm(again.position - far_position) < 1e-3


def test_distant_landmarks_are_ill_conditioned():
    rotation = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # looking along +y, level
    position = np.array([0.0, -60.0, 1.3])
    pose = Localizer(SCENE).estimate(0, exact_points(rotation, position))
    assert not pose.valid and "ill-conditioned" in pose.reason
    assert pose.position_std_m > LocalizerParams().max_position_std_m


def test_predicted_position_spread_matches_noisy_solves():
    rotations, positions = poses_along("hover_jitter")
    rng = np.random.default_rng(4)
    clean = exact_points(rotations[0], positions[0])
    errors, stds = [], []
    for trial in range(300):
        noisy = {k: (u + rng.normal(0, 1.0), v + rng.normal(0, 1.0)) for k, (u, v) in clean.items()}
        pose = Localizer(SCENE).estimate(trial, noisy)
        errors.append(np.sum((pose.position - positions[0]) ** 2))
        stds.append(pose.position_std_m)
    empirical = math.sqrt(np.mean(errors))
    assert 0.7 < empirical / np.mean(stds) < 1.3


def test_tum_round_trip_skips_invalid_rows(tmp_path):
    stamps = np.array([0.0, 0.1, 0.2])
    positions = np.array([[1.0, 2.0, 3.0], [np.nan, np.nan, np.nan], [1.5, 2.5, 3.5]])
    quaternions = np.array([[0, 0, 0, 1.0], [np.nan] * 4, [0, 0, 0.6, 0.8]])
    assert write_tum(tmp_path / "p.tum", stamps, positions, quaternions) == 2
    text = (tmp_path / "p.tum").read_text().splitlines()
    assert text[0].startswith("#") and text[1] == "0.000000 1 2 3 0 0 0 1"
    read_stamps, read_positions, read_quaternions = read_tum(tmp_path / "p.tum")
    np.testing.assert_allclose(read_stamps, [0.0, 0.2])
    np.testing.assert_allclose(read_positions, positions[[0, 2]])
    np.testing.assert_allclose(read_quaternions, quaternions[[0, 2]])


def test_malformed_tum_names_the_file_and_line(tmp_path):
    bad = tmp_path / "bad.tum"
    bad.write_text("# header\n0.0 1 2 3 0 0 0 1\n\n0.1 1 2 3\n")
    # Line 4 counts the comment and the blank line: the number a user sees in an editor.
    expected = re.escape(f"{bad}, line 4: expected 8 numbers 'timestamp tx ty tz qx qy qz qw'")
    with pytest.raises(InputError, match=f"^{expected}$"):
        read_tum(bad)
    bad.write_text("0.0 1 2 3 0 0 0 1\n0.1 1 2 three 0 0 0 1\n")
    with pytest.raises(InputError, match=re.escape(f"{bad}, line 2: expected 8 numbers")):
        read_tum(bad)
    with pytest.raises(
        InputError, match=re.escape(f"cannot read trajectory {tmp_path / 'no.tum'}")
    ):
        read_tum(tmp_path / "no.tum")


def test_association_pairs_nearest_timestamps_within_tolerance():
    index_a, index_b = associate(np.array([0.0, 0.1, 0.3]), np.array([0.1004, 0.2, 0.3, 0.0]))
    assert list(zip(index_a, index_b, strict=True)) == [(1, 0), (2, 2), (0, 3)]


def test_table3_figures_by_hand():
    gt_times = np.arange(4) / 10.0
    gt = np.zeros((4, 3))
    # Errors (cm): frame 0 (+2, 0, 0), frame 1 (0, -4, 0), frame 2 (0, 0, 2), frame 3 invalid.
    estimate = np.array([[0.02, 0, 0], [0, -0.04, 0], [0, 0, 0.02], [np.nan] * 3])
    errors = trajectory_errors(gt_times, estimate, gt_times, gt)
    np.testing.assert_allclose(errors.mean_abs_cm, (2 / 3, 4 / 3, 2 / 3))
    assert errors.rmse_cm == pytest.approx(math.sqrt((4 + 16 + 4) / 3))
    assert errors.paper_rmse_cm == pytest.approx(math.sqrt(4 / 9 + 16 / 9 + 4 / 9))
    assert (errors.frames, errors.missing_frames, errors.max_error_cm) == (3, 1, pytest.approx(4))
    table = format_table3([("(a)", errors), ("(b)", errors)])
    assert "Average" in table and "All frames" in table


def test_paper_rmse_is_the_norm_of_the_mean_abs_errors():
    # Table 3 row (a): x 1.90, y 2.25, z 2.38 -> "RMSE" 3.79; constant errors reproduce it.
    gt_times = np.arange(5) / 10.0
    offset = np.array([0.0190, -0.0225, 0.0238])
    errors = trajectory_errors(gt_times, np.tile(offset, (5, 1)), gt_times, np.zeros((5, 3)))
    assert round(errors.paper_rmse_cm, 2) == 3.79


# ---------------------------------------------------------------------------------------------
# The pipeline on a short generated sequence


@pytest.fixture(scope="session")
def short_sequence(tmp_path_factory):
    spec = SequenceSpec(
        "short", "circle", 30, seed=11, settings=RenderSettings(width=640, height=360), period_s=45
    )
    return render_sequence(tmp_path_factory.mktemp("localize") / "short", spec)


@pytest.mark.slow
def test_pipeline_on_a_generated_sequence_stays_within_three_centimetres(short_sequence):
    scene = load_scene(short_sequence / "scene.json")
    boxes = {k: v for k, v in json.loads((short_sequence / "boxes.json").read_text()).items()}
    records = list(
        localize_sequence(open_frames(short_sequence), scene, boxes, preset("autotrack"))
    )
    assert len(records) == 30
    gt_times, gt_positions, _ = read_tum(short_sequence / "poses_gt.tum")
    positions = np.array([r.pose.position for r in records])
    errors = trajectory_errors(np.arange(30) / 10.0, positions, gt_times, gt_positions)
    assert errors.missing_frames == 0, [r.pose.reason for r in records if not r.pose.valid]
    # At 640x360 a pixel is twice the angle of the paper's 1280x720 (measured: 1.8 cm).
    assert errors.rmse_cm < 3.0 and errors.max_error_cm < 8.0
    assert set(records[5].landmark_tracks) == set(scene.landmark_ids)


def test_pipeline_with_unknown_assignment_finds_the_landmarks(short_sequence):
    scene = load_scene(short_sequence / "scene.json")
    boxes = json.loads((short_sequence / "boxes.json").read_text())
    shuffled = [boxes[k] for k in ("C", "A", "D", "B")]
    frames = [open_frames(short_sequence).read(i) for i in range(3)]
    records = list(localize_sequence(frames, scene, shuffled, preset("autotrack")))
    assert set(records[0].landmark_tracks) == set(scene.landmark_ids)
    for landmark_id, track in records[0].landmark_tracks.items():
        np.testing.assert_allclose(track.box, boxes[landmark_id], atol=1.0)
    assert all(r.pose.valid for r in records)


def test_pipeline_rejects_intrinsics_for_another_image_size(short_sequence):
    scene = load_scene(short_sequence / "scene.json")
    other = replace(scene, camera=scene.camera.scaled(2.0))
    boxes = json.loads((short_sequence / "boxes.json").read_text())
    message = "frames are 640x360 but the scene's camera is calibrated for 1280x720"
    with pytest.raises(InputError, match=re.escape(message)):
        next(localize_sequence(open_frames(short_sequence), other, boxes, preset("autotrack")))


@pytest.mark.slow
def test_pipeline_survives_a_landmark_that_disappears(short_sequence):
    """Landmark C is painted over from frame 8: every frame is then a trusted pose close to the
    truth or an explicitly invalid one, never a crash or a silent wrong pose."""
    scene = load_scene(short_sequence / "scene.json")
    boxes = json.loads((short_sequence / "boxes.json").read_text())
    truth = read_ground_truth_boxes(short_sequence)

    def frames():
        with open_frames(short_sequence) as source:
            for index in range(len(source)):
                frame = source.read(index).copy()
                if index >= 8:
                    x, y, w, h = truth["C"][index]
                    frame[int(y) - 6 : int(y + h) + 6, int(x) - 6 : int(x + w) + 6] = (
                        150,
                        150,
                        145,
                    )
                yield frame

    records = list(localize_sequence(frames(), scene, boxes, preset("autotrack")))
    gt_times, gt_positions, _ = read_tum(short_sequence / "poses_gt.tum")
    for record in records:
        pose = record.pose
        if pose.valid:
            assert np.linalg.norm(pose.position - gt_positions[record.frame_index]) < 0.2
        else:
            assert pose.reason and np.all(np.isnan(pose.position))
    assert all(r.pose.valid for r in records[:8])
    # The lost landmark is noticed: left out of the pose (three-landmark poses) or frame invalid.
    noticed = [not r.pose.valid or "C" not in r.pose.used_landmarks for r in records[8:]]
    assert sum(noticed) >= len(noticed) // 2


@pytest.mark.slow
def test_cli_localize_writes_tum_and_csv_and_prints_table3(short_sequence, tmp_path, capsys):
    out, tracks = tmp_path / "poses.tum", tmp_path / "tracks.csv"
    code = main(
        [
            "localize",
            str(short_sequence),
            "--out",
            str(out),
            "--tracks",
            str(tracks),
            "--gt",
            str(short_sequence / "poses_gt.tum"),
            "--quiet",
        ]
    )
    printed = capsys.readouterr().out
    assert code == 0
    assert "frames: 30  valid poses: 30 (0 from three landmarks)" in printed
    assert "x(cm)" in printed and "RMSE" in printed and "more than 20 cm off: 0" in printed
    stamps, positions, _ = read_tum(out)
    assert len(stamps) == 30 and stamps[1] == pytest.approx(0.1)
    with tracks.open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 30 and rows[0]["valid"] == "1" and rows[0]["used"] == "A B C D"
    assert float(rows[3]["C_w"]) > 0 and rows[3]["C_aberrant"] in ("0", "1")


def test_cli_localize_reports_bad_input_in_one_line(short_sequence, tmp_path, capsys):
    bad_boxes = tmp_path / "boxes.json"
    bad_boxes.write_text('{"A": [1, 2, 3]}')
    assert main(["localize", str(short_sequence), "--init", str(bad_boxes), "--quiet"]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("autotrack: error:") and "[x, y, w, h]" in error
    assert len(error.splitlines()) == 1
    unknown = tmp_path / "unknown.json"
    unknown.write_text('{"Z": [1, 2, 30, 30]}')
    assert main(["localize", str(short_sequence), "--init", str(unknown), "--quiet"]) == 2
    assert "unknown landmark 'Z'" in capsys.readouterr().err
    outside = tmp_path / "outside.json"
    outside.write_text('{"C": [5000, 2, 30, 30]}')
    assert main(["localize", str(short_sequence), "--init", str(outside), "--quiet"]) == 2
    assert (
        "error: landmark C: box (5000.0, 2.0, 30.0, 30.0) lies outside" in capsys.readouterr().err
    )
    assert main(["localize", str(tmp_path), "--quiet"]) == 2
    assert "give --scene" in capsys.readouterr().err


def test_typical_peak_is_numpys_median_of_the_history():
    """The localizer's typical peak (statistics.median of the trusted peaks) equals np.median
    bit for bit, for odd and even history lengths; fewer than five peaks give NaN."""
    from collections import deque

    localizer = Localizer(SCENE)
    rng = np.random.default_rng(5)
    assert math.isnan(localizer._typical_peak("a"))
    for length in range(5, 31):
        history = deque(rng.random(length) * rng.choice([1e-3, 1.0, 7.0]), maxlen=30)
        localizer._peaks["a"] = history
        assert localizer._typical_peak("a") == float(np.median(history))
    localizer._peaks["a"] = deque([0.5, 0.2, 0.9, 0.4])
    assert math.isnan(localizer._typical_peak("a"))
