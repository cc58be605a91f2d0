"""Scene files: round trip, validation errors and layout warnings."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from autotrack.errors import SceneError
from autotrack.localization.camera import CameraIntrinsics
from autotrack.localization.scene import (
    Landmark,
    Scene,
    _off_line_distance,
    collinear_triples,
    load_scene,
    save_scene,
    scene_from_dict,
    scene_warnings,
)

CAMERA = {
    "fx": 920.0,
    "fy": 921.0,
    "cx": 641.3,
    "cy": 357.8,
    "distortion": [-0.045, 0.02, 0.0004, -0.0003, 0.0],
    "width": 1280,
    "height": 720,
}
LANDMARKS = [
    {"id": "A", "position": [-1.4, 6.995, 1.9], "name": "rings"},
    {"id": "B", "position": [1.3, 6.995, 1.35]},
    {"id": "C", "position": [-0.45, 4.4, 1.0]},
    {"id": "D", "position": [0.7, 3.4, 0.85]},
]


def scene_dict(**changes) -> dict:
    data = {"camera": dict(CAMERA), "landmarks": [dict(lm) for lm in LANDMARKS]}
    data.update(changes)
    return data


def write(tmp_path, data) -> str:
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(data))
    return str(path)


def test_scene_file_round_trip(tmp_path):
    scene = load_scene(write(tmp_path, scene_dict(description="lab, surveyed 2024")))
    assert scene.landmark_ids == ("A", "B", "C", "D")
    assert scene.landmark("A").name == "rings"
    assert scene.landmark("B").name is None
    np.testing.assert_array_equal(scene.landmark("C").position, [-0.45, 4.4, 1.0])
    assert scene.camera.distortion == tuple(CAMERA["distortion"])
    copy_path = tmp_path / "copy.json"
    save_scene(scene, copy_path)
    assert load_scene(copy_path) == scene


def test_camera_matrix_and_scaling_keep_pixel_centres():
    camera = CameraIntrinsics(920.0, 920.0, 639.5, 359.5, (), 1280, 720)
    np.testing.assert_array_equal(
        camera.matrix(), [[920.0, 0, 639.5], [0, 920.0, 359.5], [0, 0, 1]]
    )
    half = camera.scaled(0.5)
    # The centre of a 1280-wide image (639.5) is the centre of the 640-wide one (319.5).
    assert (half.cx, half.cy, half.fx, half.width, half.height) == (319.5, 179.5, 460.0, 640, 360)


def test_fewer_than_four_landmarks_is_an_error(tmp_path):
    path = write(tmp_path, scene_dict(landmarks=LANDMARKS[:3]))
    with pytest.raises(SceneError, match="3 landmark.*at least 4"):
        load_scene(path)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d["camera"].pop("fx"), "camera is missing field.*fx"),
        (lambda d: d["landmarks"][1].pop("position"), r"landmarks\[1\] is missing field.*position"),
        (lambda d: d.pop("camera"), "scene is missing field.*camera"),
        (lambda d: d["camera"].update(fx=-3.0), "fx and camera.fy must be positive"),
        (lambda d: d["camera"].update(width=12.5), "width must be a positive whole number"),
        (lambda d: d["camera"].update(distortion=[0.1, 0.2, 0.3]), "3 coefficients"),
        (lambda d: d["camera"].update(focal=900), "unknown field.*focal"),
        (lambda d: d["landmarks"][0].update(position=[1, 2]), r"position must be \[x, y, z\]"),
        (lambda d: d["landmarks"][0].update(position=[1, "a", 2]), "must be a finite number"),
        (lambda d: d["landmarks"][2].update(id="A"), "duplicate landmark id.*A"),
        (lambda d: d["landmarks"][3].update(position=[-1.4, 6.995, 1.9]), "less than 1 cm apart"),
    ],
)
def test_malformed_scene_names_the_problem(tmp_path, mutate, message):
    data = scene_dict()
    mutate(data)
    with pytest.raises(SceneError, match=message) as error:
        load_scene(write(tmp_path, data))
    assert "scene.json" in str(error.value)


def test_invalid_json_reports_line(tmp_path):
    path = tmp_path / "scene.json"
    path.write_text('{"camera": {\n"fx": 1,,}')
    with pytest.raises(SceneError, match="not valid JSON.*line 2"):
        load_scene(path)


def test_missing_file_is_a_scene_error(tmp_path):
    with pytest.raises(SceneError, match="cannot read scene file"):
        load_scene(tmp_path / "nope.json")


def test_collinear_landmarks_are_rejected():
    line = [{"id": str(i), "position": [0.5 * i, 3.0, 1.0]} for i in range(4)]
    with pytest.raises(SceneError, match="one line"):
        scene_from_dict(scene_dict(landmarks=line))


def test_good_layout_has_no_warnings():
    assert scene_warnings(scene_from_dict(scene_dict())) == []


def test_coplanar_layout_is_warned():
    flat = [
        {"id": "A", "position": [-1.0, 5.0, 2.0]},
        {"id": "B", "position": [1.2, 5.0, 1.6]},
        {"id": "C", "position": [-0.4, 5.0, 0.7]},
        {"id": "D", "position": [0.9, 5.0, 0.3]},
    ]
    warnings = scene_warnings(scene_from_dict(scene_dict(landmarks=flat)))
    assert any("coplanar" in w for w in warnings)
    assert not any("symmetric" in w for w in warnings)


def test_symmetric_layout_is_warned():
    square = [
        {"id": "A", "position": [0.0, 5.0, 0.0]},
        {"id": "B", "position": [1.0, 5.0, 0.0]},
        {"id": "C", "position": [1.0, 5.0, 1.0]},
        {"id": "D", "position": [0.0, 5.0, 1.0]},
    ]
    warnings = scene_warnings(scene_from_dict(scene_dict(landmarks=square)))
    assert any("symmetric" in w for w in warnings)


def test_three_collinear_landmarks_are_warned():
    layout = [
        {"id": "A", "position": [0.0, 5.0, 1.0]},
        {"id": "B", "position": [1.0, 5.0, 1.0]},
        {"id": "C", "position": [2.0, 5.0, 1.0]},
        {"id": "D", "position": [0.7, 3.5, 0.2]},
    ]
    warnings = scene_warnings(scene_from_dict(scene_dict(landmarks=layout)))
    assert any("A, B, C are (nearly) collinear" in w for w in warnings)


def test_unknown_landmark_lookup_lists_known_ids():
    scene = Scene(
        CameraIntrinsics(900, 900, 640, 360, (), 1280, 720),
        tuple(Landmark(lm["id"], np.array(lm["position"])) for lm in LANDMARKS),
    )
    with pytest.raises(SceneError, match="unknown landmark 'E'.*A, B, C, D"):
        scene.landmark("E")
    np.testing.assert_array_equal(scene.object_points(["D", "A"])[1], LANDMARKS[0]["position"])


def _collinear_triples_by_svd(points: np.ndarray, spread_m: float) -> list[tuple[int, ...]]:
    """The former check: one SVD per triple (cubic), kept here as the reference."""
    return [
        triple
        for triple in itertools.combinations(range(len(points)), 3)
        if _off_line_distance(points[list(triple)]) < spread_m
    ]


def _random_layout(rng: np.random.Generator, count: int) -> np.ndarray:
    """Landmarks in a room-sized box, with some planted on lines through others (jittered
    by up to a few centimetres, so some fall each side of the threshold)."""
    points = rng.uniform([-3.0, 2.0, 0.0], [3.0, 9.0, 2.5], size=(count, 3))
    for index in range(3, count, 4):
        a, b = points[rng.integers(0, index, size=2)]
        points[index] = a + rng.uniform(-0.5, 1.5) * (b - a) + rng.normal(0.0, 0.03, size=3)
    return points


@pytest.mark.parametrize("seed", range(6))
def test_collinear_triples_match_the_per_triple_svd(seed):
    rng = np.random.default_rng(seed)
    points = _random_layout(rng, int(rng.integers(8, 40)))
    size = float(np.linalg.norm(points - points.mean(axis=0), axis=1).max())
    for spread in (0.01, 0.03 * size, 0.1 * size):
        expected = _collinear_triples_by_svd(points, spread)
        assert collinear_triples(points, spread) == expected
    assert _collinear_triples_by_svd(points, 0.03 * size)  # the planted lines give some


def test_scene_with_400_landmarks_is_checked():
    rng = np.random.default_rng(400)
    points = _random_layout(rng, 400)
    landmarks = [{"id": f"L{i}", "position": p.tolist()} for i, p in enumerate(points)]
    scene = scene_from_dict(scene_dict(landmarks=landmarks))
    warnings = scene_warnings(scene)
    assert len(scene.landmark_ids) == 400
    assert any("collinear" in w for w in warnings)
