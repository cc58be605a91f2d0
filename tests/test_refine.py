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
    to_grey,
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


def render_on_moving_wall(homography: np.ndarray, wall_shift: tuple[float, float]) -> np.ndarray:
    """An RGB frame: the texture warped by `homography` in front of a textured wall that is
    shifted by `wall_shift` pixels (a wall at another depth: parallax)."""
    rng = np.random.default_rng(7)
    wall = cv2.resize(rng.uniform(40, 220, (60, 80, 3)).astype(np.float32), SIZE)
    wall = cv2.warpAffine(
        wall,
        np.array([[1, 0, wall_shift[0]], [0, 1, wall_shift[1]]]),
        SIZE,
        borderMode=cv2.BORDER_REFLECT,
    )
    warped = cv2.warpPerspective(TEXTURE, homography, SIZE, flags=cv2.INTER_LINEAR)
    mask = cv2.warpPerspective(np.ones(TEXTURE.shape[:2], np.float32), homography, SIZE)
    frame = wall * (1 - mask[..., None]) + warped.astype(np.float32) * mask[..., None]
    frame += np.random.default_rng(8).normal(0, 2.0, frame.shape)
    return np.clip(frame, 0, 255).astype(np.uint8)[..., ::-1].copy()


@pytest.mark.parametrize("fraction", [1.0, 0.7])
def test_template_is_the_central_part_of_the_box(fraction):
    first = placement(0.3, 0.0, (150.0, 110.0))
    refiner = PointRefiner(RefineParams(template_fraction=fraction))
    box = box_around(true_point(first), 100.0)
    refiner.init(render_on_moving_wall(first, (0.0, 0.0)), {"C": box})
    image, centre = refiner.template_of("C")
    assert image.shape == (100, 100)  # re-acquisition matches the whole first box
    assert centre == pytest.approx((50.0, 50.0))
    later = placement(0.3, 0.0, (152.6, 108.7))
    result = refiner.refine(render_on_moving_wall(later, (0.0, 0.0)), {"C": box})["C"]
    assert result.refined, result.reason
    assert math.dist(result.point, true_point(later)) < 0.1


def test_the_wall_behind_the_landmark_is_left_out_of_the_alignment():
    # The first box is larger than the landmark (a bounding box): its border holds wall, which
    # moves by another amount than the landmark (parallax) and breaks the whole box's
    # homography; the central part is the landmark alone.
    first = placement(0.3, 0.0, (150.0, 110.0))
    later = placement(0.3, 0.0, (152.6, 108.7))
    results = {}
    for fraction in (1.0, 0.7):
        refiner = PointRefiner(RefineParams(template_fraction=fraction))
        refiner.init(
            render_on_moving_wall(first, (0.0, 0.0)), {"C": box_around(true_point(first), 100)}
        )
        moved = render_on_moving_wall(later, (5.0, 2.0))
        results[fraction] = refiner.refine(moved, {"C": box_around(true_point(later), 100)})["C"]
    assert results[0.7].refined and results[1.0].refined
    assert results[1.0].correlation < 0.97 < 0.99 < results[0.7].correlation
    assert math.dist(results[0.7].point, true_point(later)) < 0.05
    assert math.dist(results[0.7].point, true_point(later)) < math.dist(
        results[1.0].point, true_point(later)
    )


def test_an_rgb_frame_aligns_exactly_as_its_grey_image():
    # Only the crop around the landmark is converted to grey: the same numbers as the grey of
    # the whole frame.
    later = placement(0.318, 3.0, (157.37, 104.62))
    box = box_around(true_point(later), 0.318 * 256, offset=(2.4, -1.8))
    frame = render(later, 1)
    from_rgb = started_refiner().refine(frame, {"C": box})["C"]
    from_grey = started_refiner().refine(to_grey(frame), {"C": box})["C"]
    assert from_rgb.refined
    assert from_rgb == from_grey


def test_a_box_too_small_for_its_central_part_aligns_the_whole_box():
    frame = render(placement(0.05, 0.0, (150.0, 110.0)), 0)
    refiner = PointRefiner(RefineParams(template_fraction=0.7))
    refiner.init(frame, {"small": (145.0, 105.0, 10.0, 10.0), "tiny": (145.0, 105.0, 7.0, 7.0)})
    assert refiner.has_template("small")  # 7 px of central part: the whole 10 px box instead
    assert refiner.template_of("small")[0].shape == (10, 10)
    assert not refiner.has_template("tiny")
    result = refiner.refine(frame, {"small": (145.0, 105.0, 10.0, 10.0)})["small"]
    assert result.reason != "no template"
