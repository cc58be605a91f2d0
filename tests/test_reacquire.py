"""Out-of-view gating and re-acquisition of lost landmarks from the pose prediction, and the
hard cases of the test bed (which landmark is hidden when, the rendered files)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from autotrack.localization.camera import project_points
from autotrack.localization.reacquire import LandmarkKeeper, ReacquireParams, match_scaled_template
from autotrack.localization.refine import PointRefiner, to_grey
from autotrack.result import PoseEstimate
from autotrack.synthetic.renderer import Renderer
from autotrack.synthetic.scenarios import (
    CASES,
    Occluder,
    ScenarioSpec,
    hidden_spans,
    read_visibility,
    render_scenario,
    scenario_specs,
    visibility,
)
from autotrack.synthetic.trajectories import (
    RenderSettings,
    SequenceSpec,
    ground_truth_poses,
    yaw_pitch,
)
from autotrack.synthetic.world import default_camera, default_scene, landmark_box

CAMERA = default_camera(640, 360)
SCENE = default_scene(CAMERA)


def pose_estimate(index, rotation, position, used=("A", "B", "C", "D")) -> PoseEstimate:
    return PoseEstimate(index, True, rotation, position, {}, tuple(used))


@pytest.fixture(scope="module")
def flight():
    spec = SequenceSpec("t", "circle", 40, seed=5, settings=RenderSettings(640, 360), period_s=40)
    _, rotations, positions = ground_truth_poses(spec)
    renderer = Renderer(CAMERA, seed=5, noise_sigma=1.0)
    return rotations, positions, renderer


def first_boxes(rotation, position):
    return {k: landmark_box(CAMERA, k, rotation, position) for k in SCENE.landmark_ids}


def test_a_landmark_the_pose_puts_outside_the_image_is_out_of_view(flight):
    rotations, positions, _ = flight
    keeper = LandmarkKeeper(SCENE)
    blank = np.zeros((360, 640), np.float32)
    boxes = first_boxes(rotations[0], positions[0])
    keeper.observe(0, blank, pose_estimate(0, rotations[0], positions[0]), boxes, {})
    assert keeper.out_of_view(1) == {}
    turned = yaw_pitch(rotations[1], math.radians(20.0), 0.0)  # D leaves on the right
    keeper.observe(1, blank, pose_estimate(1, turned, positions[1], ("A", "B", "C")), boxes, {})
    assert keeper.out_of_view(2) == {"D": "out of view"}
    # The prediction is only trusted while the pose is recent.
    assert keeper.out_of_view(1 + ReacquireParams().max_prior_age_frames + 1) == {}


def _first_frame_templates(flight):
    """The flight's first frame (RGB), its landmark boxes and the refiner's templates of them."""
    rotations, positions, renderer = flight
    frame0 = renderer.render(rotations[0], positions[0])[..., ::-1].copy()
    boxes = first_boxes(rotations[0], positions[0])
    refiner = PointRefiner()
    refiner.init(frame0, boxes)
    return frame0, boxes, {k: refiner.template_of(k) for k in boxes}


def test_lost_landmark_is_found_where_the_pose_predicts_it(flight):
    rotations, positions, renderer = flight
    frame0, boxes, templates = _first_frame_templates(flight)
    keeper = LandmarkKeeper(SCENE, ReacquireParams(lost_frames=2))
    keeper.observe(0, to_grey(frame0), pose_estimate(0, rotations[0], positions[0]), boxes, {})
    found = []
    for k in (20, 21):  # C left out of two trusted poses in a row
        frame = renderer.render(rotations[k], positions[k])[..., ::-1].copy()
        pose = pose_estimate(k, rotations[k], positions[k], ("A", "B", "D"))
        found = keeper.observe(k, to_grey(frame), pose, boxes, templates)
        if k == 20:
            assert found == []  # not yet lost long enough
    assert [f.landmark_id for f in found] == ["C"]
    x, y, w, h = found[0].box
    truth = project_points(CAMERA, SCENE.object_points(("C",)), rotations[21], positions[21])[0]
    assert math.dist((x + w / 2, y + h / 2), truth) < 2.0
    assert found[0].match > 0.8
    true_box = landmark_box(CAMERA, "C", rotations[21], positions[21])
    assert w == pytest.approx(true_box[2], rel=0.1)


def test_an_rgb_frame_is_searched_exactly_as_its_grey_image(flight):
    # Only the search window is converted to grey: the same match as in the whole frame's grey.
    rotations, positions, renderer = flight
    frame0, boxes, templates = _first_frame_templates(flight)
    frame = renderer.render(rotations[21], positions[21])[..., ::-1].copy()
    pose = pose_estimate(21, rotations[21], positions[21], ("A", "B", "D"))
    found = {}
    for kind, image in (("rgb", frame), ("grey", to_grey(frame))):
        keeper = LandmarkKeeper(SCENE, ReacquireParams(lost_frames=1))
        keeper.observe(0, frame0, pose_estimate(0, rotations[0], positions[0]), boxes, {})
        found[kind] = keeper.observe(21, image, pose, boxes, templates)
    assert [f.landmark_id for f in found["rgb"]] == ["C"]
    assert found["rgb"] == found["grey"]


def test_a_still_covered_landmark_is_not_restarted(flight):
    rotations, positions, renderer = flight
    frame0, boxes, templates = _first_frame_templates(flight)
    keeper = LandmarkKeeper(SCENE, ReacquireParams(lost_frames=1))
    keeper.observe(0, to_grey(frame0), pose_estimate(0, rotations[0], positions[0]), boxes, {})
    frame = renderer.render(rotations[10], positions[10])[..., ::-1].copy()
    x, y, w, h = (int(round(v)) for v in landmark_box(CAMERA, "C", rotations[10], positions[10]))
    frame[y - 8 : y + h + 8, x - 8 : x + w + 8] = (160, 140, 120)  # a board in front of C
    pose = pose_estimate(10, rotations[10], positions[10], ("A", "B", "D"))
    assert keeper.observe(10, to_grey(frame), pose, boxes, templates) == []


def test_scaled_template_match_finds_the_pattern_at_another_size():
    rng = np.random.default_rng(1)
    template = rng.uniform(0, 255, (40, 40)).astype(np.float32)
    template = np.kron(template[::4, ::4], np.ones((4, 4), np.float32))

    image = rng.uniform(0, 255, (200, 200)).astype(np.float32)
    large = cv2.resize(template, (60, 60), interpolation=cv2.INTER_LINEAR)
    image[70:130, 50:110] = large
    score, centre = match_scaled_template(image, template, (20.0, 20.0), 1.5, (85.0, 95.0), 12.0)
    assert score > 0.9
    assert math.dist(centre, (80.0, 100.0)) <= 1.0


def test_hard_cases_hide_the_landmarks_they_promise():
    hidden = {}
    for spec in scenario_specs(seed=0, frames=250):
        path = spec.camera_path()
        poses = [path(k / 10.0) for k in range(spec.sequence.frames)]
        fractions = visibility(
            spec, np.stack([r for r, _ in poses]), np.stack([p for _, p in poses])
        )
        hidden[spec.case] = {k: hidden_spans(v) for k, v in fractions.items() if hidden_spans(v)}
    assert list(hidden) == list(CASES)
    assert set(hidden["occlusion"]) == {"C"}
    assert set(hidden["leave_view"]) == {"D"}
    assert set(hidden["occlusion_and_turn"]) == {"A", "D"}
    assert hidden["blur_bursts"] == {} and hidden["lighting"] == {}
    for case in ("occlusion", "leave_view", "occlusion_and_turn"):
        for spans in hidden[case].values():
            for start, back in spans:
                assert 10 <= back - start <= 30, (case, start, back)  # 1-3 s at 10 fps


def test_rendered_case_records_visibility_and_hides_the_landmark(tmp_path):
    base = SequenceSpec("occ", "circle", 3, seed=2, settings=RenderSettings(320, 180))
    spec = ScenarioSpec("occlusion", base, occluders=(Occluder("C", 0.1, speed_m_s=0.3),))
    folder = render_scenario(tmp_path / "occ", spec)
    assert len(list((folder / "img").glob("*.jpg"))) == 3
    fractions = read_visibility(folder)
    assert fractions["C"][1] < 0.5 and fractions["A"][1] > 0.99
    metadata = json.loads((folder / "sequence.json").read_text())
    assert metadata["case"] == "occlusion" and "C" in metadata["hidden"]
    unoccluded = render_scenario(tmp_path / "clear", replace(spec, occluders=()))

    x, y, w, h = (int(v) for v in np.loadtxt(folder / "groundtruth" / "C.txt", delimiter=",")[1])
    covered = cv2.imread(str(folder / "img" / "00002.jpg"))[y : y + h, x : x + w]
    clear = cv2.imread(str(unoccluded / "img" / "00002.jpg"))[y : y + h, x : x + w]
    assert np.abs(covered.astype(float) - clear).mean() > 20
