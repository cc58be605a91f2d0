"""The synthetic test bed: files, determinism, ground truth that agrees with the pixels."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from autotrack.cli import main
from autotrack.io.tum import read_tum
from autotrack.localization.camera import project_points
from autotrack.localization.scene import load_scene, scene_warnings
from autotrack.synthetic.renderer import Renderer, render_sequence
from autotrack.synthetic.testbed import read_ground_truth_boxes, sequence_specs
from autotrack.synthetic.trajectories import (
    PAPER_FRAME_COUNTS,
    TRAJECTORIES,
    RenderSettings,
    SequenceSpec,
    frame_conditions,
    ground_truth_poses,
)
from autotrack.synthetic.world import default_camera, visibility_problems

SMALL = RenderSettings(width=640, height=360)


@pytest.fixture(scope="session")
def sequence(tmp_path_factory):
    spec = SequenceSpec("short", "figure_eight", 12, seed=5, settings=SMALL, period_s=40.0)
    return render_sequence(tmp_path_factory.mktemp("synthetic") / "short", spec), spec


def read_rgb(path):
    return cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)


def test_sequence_folder_layout(sequence):
    folder, spec = sequence
    frames = sorted((folder / "img").glob("*.jpg"))
    assert [p.name for p in frames[:2]] == ["00001.jpg", "00002.jpg"] and len(frames) == 12
    assert read_rgb(frames[0]).shape == (360, 640, 3)
    metadata = json.loads((folder / "sequence.json").read_text())
    assert (metadata["trajectory"], metadata["frames"], metadata["fps"]) == (
        "figure_eight",
        12,
        10.0,
    )
    scene = load_scene(folder / "scene.json")
    assert scene.landmark_ids == ("A", "B", "C", "D")
    assert (scene.camera.width, scene.camera.height) == (640, 360)
    assert scene.camera.distortion == SMALL.distortion
    assert scene_warnings(scene) == []
    boxes = json.loads((folder / "boxes.json").read_text())
    truth = read_ground_truth_boxes(folder)
    for landmark_id, box in boxes.items():
        assert truth[landmark_id].shape == (12, 4)
        np.testing.assert_allclose(box, truth[landmark_id][0], atol=0.006)


def test_ground_truth_poses_are_written_as_tum(sequence):
    folder, spec = sequence
    stamps, positions, quaternions = read_tum(folder / "poses_gt.tum")
    expected_stamps, _, expected_positions = ground_truth_poses(spec)
    np.testing.assert_allclose(stamps, expected_stamps)
    np.testing.assert_allclose(positions, expected_positions, atol=1e-8)
    np.testing.assert_allclose(np.linalg.norm(quaternions, axis=1), 1.0, atol=1e-8)


def test_rendering_is_deterministic(tmp_path):
    spec = SequenceSpec(
        "d", "hover_jitter", 3, seed=9, settings=RenderSettings(width=320, height=180)
    )
    first = render_sequence(tmp_path / "one", spec)
    second = render_sequence(tmp_path / "two", spec)
    for name in ("img/00001.jpg", "img/00003.jpg", "poses_gt.tum", "boxes.json", "scene.json"):
        assert (first / name).read_bytes() == (second / name).read_bytes()
    other = render_sequence(
        tmp_path / "three", SequenceSpec("d", "hover_jitter", 3, 10, spec.settings)
    )
    assert (first / "img/00001.jpg").read_bytes() != (other / "img/00001.jpg").read_bytes()


def test_landmarks_appear_where_the_ground_truth_puts_them(sequence):
    """Each pattern's dominant colour is inside its ground-truth box, centred on the projected
    landmark centre (lens distortion included)."""
    folder, _ = sequence
    scene = load_scene(folder / "scene.json")
    stamps, positions, quaternions = read_tum(folder / "poses_gt.tum")
    from scipy.spatial.transform import Rotation

    truth = read_ground_truth_boxes(folder)
    for frame in (0, 11):
        image = read_rgb(folder / "img" / f"{frame + 1:05d}.jpg").astype(int)
        rotation = Rotation.from_quat(quaternions[frame]).as_matrix()
        centres = project_points(scene.camera, scene.object_points(), rotation, positions[frame])
        red, green, blue = image[..., 0], image[..., 1], image[..., 2]
        masks = {
            "A": red - np.maximum(green, blue) > 40,  # red rings
            "B": blue - np.maximum(red, green) > 40,  # blue checkerboard
        }
        for landmark_id, mask in masks.items():
            x, y, w, h = truth[landmark_id][frame]
            inside = mask[int(y) : int(np.ceil(y + h)), int(x) : int(np.ceil(x + w))]
            assert inside.sum() > 0.15 * w * h
            rows, cols = np.nonzero(mask)
            near = np.hypot(cols - (x + w / 2), rows - (y + h / 2)) < max(w, h)
            centroid = np.array([cols[near].mean(), rows[near].mean()])
            row = scene.landmark_ids.index(landmark_id)
            assert np.linalg.norm(centroid - centres[row]) < 1.5


def test_six_trajectories_keep_every_landmark_cleanly_in_view():
    for spec in sequence_specs():
        _, rotations, positions = ground_truth_poses(spec)
        camera = default_camera(1280, 720, spec.settings.distortion)
        assert visibility_problems(camera, rotations, positions, margin_px=4.0) == []
    assert [s.trajectory for s in sequence_specs()] == list(TRAJECTORIES)
    assert [s.frames for s in sequence_specs()] == list(PAPER_FRAME_COUNTS)
    assert sum(PAPER_FRAME_COUNTS) == 2666


def test_trajectories_differ_and_move_like_a_small_uav():
    paths = []
    for spec in sequence_specs():
        _, _, positions = ground_truth_poses(spec)
        steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
        assert steps.max() < 0.08  # below 0.8 m/s at 10 fps
        paths.append(positions[:300])
    for a in range(6):
        for b in range(a + 1, 6):
            assert np.abs(paths[a] - paths[b]).max() > 0.2


def test_lighting_changes_and_long_exposure_bursts():
    spec = sequence_specs()[0]
    conditions = frame_conditions(spec)
    brightness = conditions.gain
    assert brightness.max() - brightness.min() > 0.3
    assert conditions.gamma.max() - conditions.gamma.min() > 0.2
    burst = conditions.exposure_s > spec.settings.exposure_s
    assert 0.05 < burst.mean() < 0.2


def test_motion_blur_softens_the_frame():
    camera = default_camera(640, 360)
    renderer = Renderer(camera, seed=1, noise_sigma=0.0)
    _, rotations, positions = ground_truth_poses(SequenceSpec("b", "circle", 2, 1, SMALL))
    sharp = renderer.render(rotations[0], positions[0])
    blurred = renderer.render(rotations[0], positions[0], blur_px=(9.0, 2.0))
    energy = [
        cv2.Laplacian(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY), cv2.CV_64F).var()
        for f in (sharp, blurred)
    ]
    assert energy[1] < 0.5 * energy[0]
    darker = renderer.render(rotations[0], positions[0], gain=0.6)
    assert darker.mean() < 0.7 * sharp.mean()


def test_cli_synth_generates_the_requested_sequences(tmp_path, capsys):
    code = main(
        ["synth", str(tmp_path), "--sequences", "2", "--frames", "3", "--width", "320", "--quiet"]
    )
    assert code == 0
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_dir()) == [
        "a_circle",
        "b_figure_eight",
    ]
    assert len(list((tmp_path / "b_figure_eight" / "img").glob("*.jpg"))) == 3
    assert "b_figure_eight" in capsys.readouterr().out
    assert "| a_circle | circle | 3 |" in (tmp_path / "README.md").read_text()


def test_cli_synth_rejects_a_bad_width(tmp_path, capsys):
    assert main(["synth", str(tmp_path), "--width", "333"]) == 2
    assert "multiple of 16" in capsys.readouterr().err
