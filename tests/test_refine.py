"""Sub-pixel landmark points: the template alignment recovers the landmark's true point from a
box that is pixels off, follows scale and rotation, and falls back to the box centre when the
landmark is covered or the tracker is elsewhere."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from autotrack.localization.refine import (
    PointRefiner,
    RefineParams,
    about_point,
    homography_scale,
    map_point,
)
from autotrack.synthetic.textures import landmark_texture

SIZE = (320, 240)
TEXTURE = landmark_texture("star", np.random.default_rng(0))


def render(homography: np.ndarray, seed: int, texture: np.ndarray = TEXTURE) -> np.ndarray:
    """An RGB frame: the texture warped by `homography` (texel -> image) on a mottled wall."""
    rng = np.random.default_rng(seed)
    wall = cv2.resize(rng.uniform(90, 170, (30, 40, 3)).astype(np.float32), SIZE)
    warped = cv2.warpPerspective(texture, homography, SIZE, flags=cv2.INTER_LINEAR)
    mask = cv2.warpPerspective(np.ones(texture.shape[:2], np.float32), homography, SIZE)
    frame = wall * (1 - mask[..., None]) + warped.astype(np.float32) * mask[..., None]
    frame += rng.normal(0, 2.0, frame.shape)
    return np.clip(frame, 0, 255).astype(np.uint8)[..., ::-1].copy()


def placement(scale: float, angle_deg: float, centre: tuple[float, float]) -> np.ndarray:
    """Texel -> image homography: the texture's centre at `centre`, scaled and rotated, with a
    little perspective."""
    n = TEXTURE.shape[0]
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    to_origin = np.array([[1, 0, -(n - 1) / 2], [0, 1, -(n - 1) / 2], [0, 0, 1.0]])
    turn = np.array([[scale * c, -scale * s, 0], [scale * s, scale * c, 0], [0, 0, 1.0]])
    tilt = np.array([[1, 0, 0], [0, 1, 0], [2e-4, 0, 1.0]])
    place = np.array([[1, 0, centre[0]], [0, 1, centre[1]], [0, 0, 1.0]])
    return place @ tilt @ turn @ to_origin


def true_point(homography: np.ndarray) -> tuple[float, float]:
    n = TEXTURE.shape[0]
    return map_point(homography, ((n - 1) / 2, (n - 1) / 2))


def box_around(point: tuple[float, float], side: float, offset=(0.0, 0.0)):
    return (point[0] + offset[0] - side / 2, point[1] + offset[1] - side / 2, side, side)


def started_refiner(params: RefineParams | None = None):
    first = placement(0.3, 0.0, (150.0, 110.0))
    refiner = PointRefiner(params or RefineParams())
    refiner.init(render(first, 0), {"C": box_around(true_point(first), 0.3 * 256)})
    return refiner


def test_refined_point_lands_on_the_landmark_when_the_box_is_pixels_off():
    refiner = started_refiner()
    # Next frame: moved by a sub-pixel amount, 6 % larger, turned 3 degrees.
    later = placement(0.318, 3.0, (157.37, 104.62))
    truth = true_point(later)
    box = box_around(truth, 0.318 * 256, offset=(2.4, -1.8))
    result = refiner.refine(render(later, 1), {"C": box})["C"]
    assert result.refined, result.reason
    assert result.correlation > 0.9
    assert math.dist(result.point, truth) < 0.15
    assert math.dist((box[0] + box[2] / 2, box[1] + box[3] / 2), truth) > 2.9


def test_refinement_follows_the_landmark_over_frames_without_drift():
    refiner = started_refiner()
    errors = []
    for k in range(1, 15):
        later = placement(0.3 + 0.004 * k, 0.7 * k, (150.0 + 2.3 * k, 110.0 - 1.1 * k))
        truth = true_point(later)
        offset = (1.5 * math.sin(k), 1.5 * math.cos(k))  # a wandering tracker
        result = refiner.refine(render(later, k), {"C": box_around(truth, 77 + k, offset)})["C"]
        assert result.refined, result.reason
        errors.append(math.dist(result.point, truth))
    assert max(errors) < 0.2


def test_covered_landmark_falls_back_to_the_box_centre():
    refiner = started_refiner()
    later = placement(0.3, 0.0, (152.0, 111.0))
    covered = render(later, 1, texture=np.full_like(TEXTURE, 140))
    box = box_around(true_point(later), 77)
    result = refiner.refine(covered, {"C": box})["C"]
    assert not result.refined
    assert result.point == pytest.approx((box[0] + box[2] / 2, box[1] + box[3] / 2))
    assert result.reason


def test_tracker_far_from_the_landmark_is_not_overridden():
    # The tracker sits 30 px off on the wall: the alignment either fails or must not pull the
    # point back over that distance; the tracker's centre is kept either way.
    refiner = started_refiner(RefineParams(max_offset_fraction=0.1, min_offset_px=3.0))
    later = placement(0.3, 0.0, (150.0, 110.0))
    box = box_around(true_point(later), 77, offset=(30.0, 0.0))
    result = refiner.refine(render(later, 1), {"C": box})["C"]
    assert not result.refined
    assert result.point == pytest.approx((box[0] + box[2] / 2, box[1] + box[3] / 2))


def test_homography_helpers():
    h = about_point((10.0, 20.0), 2.0, (1.0, -1.0))
    assert map_point(h, (10.0, 20.0)) == pytest.approx((11.0, 19.0))
    assert map_point(h, (11.0, 20.0)) == pytest.approx((13.0, 19.0))
    assert homography_scale(h, (3.0, 4.0)) == pytest.approx(2.0)
