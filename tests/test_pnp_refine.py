"""The weighted pose refinement: a minimum of the weighted cost (zero gradient), never worse
than where it starts, and the outlier checks built on it unchanged."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from autotrack.errors import InputError
from autotrack.localization.camera import project_points
from autotrack.localization.localizer import Localizer
from autotrack.localization.pnp import reprojection, weighted_refinement
from autotrack.synthetic.trajectories import RenderSettings, SequenceSpec, ground_truth_poses
from autotrack.synthetic.world import default_camera, default_scene

CAMERA = default_camera(1280, 720, RenderSettings().distortion)
SCENE = default_scene(CAMERA)
WEIGHTS = np.array([1.0, 0.25, 1.0, 0.5])


def _poses(trajectory: str, frames: int = 40):
    _, rotations, positions = ground_truth_poses(SequenceSpec("t", trajectory, frames, seed=3))
    return rotations, positions


def _cost(params: np.ndarray, image_points: np.ndarray) -> float:
    projected, _ = reprojection(CAMERA, SCENE.object_points(), params[:3], params[3:])
    return float(np.sum(np.repeat(WEIGHTS, 2) * (projected - image_points).reshape(-1) ** 2))


def _gradient(params: np.ndarray, image_points: np.ndarray) -> np.ndarray:
    """d cost / d (rvec | tvec) of the weighted cost (halved), from OpenCV's Jacobian."""
    projected, jac = reprojection(CAMERA, SCENE.object_points(), params[:3], params[3:])
    return jac.T @ (np.repeat(WEIGHTS, 2) * (projected - image_points).reshape(-1))


def _noisy_points(rng, rotation, position) -> np.ndarray:
    exact = project_points(CAMERA, SCENE.object_points(), rotation, position)
    return exact + rng.normal(0.0, 1.5, exact.shape)


def _sqpnp(image_points: np.ndarray) -> np.ndarray:
    _, rvec, tvec = cv2.solvePnP(
        SCENE.object_points().reshape(-1, 1, 3),
        image_points.reshape(-1, 1, 2),
        CAMERA.matrix(),
        CAMERA.distortion_array(),
        flags=cv2.SOLVEPNP_SQPNP,
    )
    return np.concatenate([rvec.reshape(3), tvec.reshape(3)])


def test_weighted_refinement_reaches_the_weighted_minimum():
    """Zero gradient of the weighted cost, and a cost no higher than the unweighted minimum's."""
    rng = np.random.default_rng(7)
    for trajectory in ("circle", "figure_eight", "approach_retreat"):
        rotations, positions = _poses(trajectory)
        for frame in range(0, 40, 8):
            points = _noisy_points(rng, rotations[frame], positions[frame])
            start = _sqpnp(points)
            ours = weighted_refinement(CAMERA, SCENE.object_points(), points, start, WEIGHTS)
            unweighted = weighted_refinement(
                CAMERA, SCENE.object_points(), points, start, np.ones(len(WEIGHTS))
            )
            # The start (SQPnP, the unweighted minimum) is not the weighted one: its gradient is
            # what a solver ignoring the weights would leave.
            left = np.abs(_gradient(ours, points)).max()
            assert left < 1e-3 * np.abs(_gradient(start, points)).max()
            assert _cost(ours, points) <= _cost(unweighted, points) * (1 + 1e-9)


def test_weighted_refinement_from_a_wrong_start_never_ends_worse():
    """A start far from the pose (a wrong guess): every accepted step lowers the cost."""
    rng = np.random.default_rng(3)
    rotations, positions = _poses("circle")
    points = _noisy_points(rng, rotations[10], positions[10])
    good = _sqpnp(points)
    for offset in ([0.3, -0.2, 0.1, 0.8, -0.5, 1.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]):
        start = good + np.array(offset)
        refined = weighted_refinement(CAMERA, SCENE.object_points(), points, start, WEIGHTS)
        assert _cost(refined, points) <= _cost(start, points)


def test_outlier_is_still_rejected_when_a_landmark_is_down_weighted():
    """An aberrant (down-weighted) landmark sends the pose through the weighted refinement; a
    landmark 40 px off is still found and left out, with the previous pose's help."""
    rotations, positions = _poses("approach_retreat")
    localizer = Localizer(SCENE)
    first = project_points(CAMERA, SCENE.object_points(), rotations[0], positions[0])
    localizer.estimate(0, dict(zip(SCENE.landmark_ids, map(tuple, first), strict=True)))
    points = project_points(CAMERA, SCENE.object_points(), rotations[1], positions[1])
    by_id = dict(zip(SCENE.landmark_ids, map(tuple, points), strict=True))
    by_id["D"] = (by_id["D"][0] + 40.0, by_id["D"][1] - 15.0)
    pose = localizer.estimate(1, by_id, aberrant={"B": True})
    assert pose.valid, pose.reason
    assert "D" not in pose.used_landmarks
    assert pose.excluded_landmarks["D"].startswith("outlier: ")
    assert math.isclose(
        float(pose.excluded_landmarks["D"].split()[1]), math.hypot(40, 15), abs_tol=0.2
    )
    assert np.linalg.norm(pose.position - positions[1]) < 1e-3


def _weighted_cost(points: np.ndarray):
    """The weighted reprojection residuals and their Jacobian, as scipy's solvers take them."""
    scale = np.repeat(np.sqrt(WEIGHTS), 2)
    object_points = SCENE.object_points()

    def residuals(params):
        projected, _ = reprojection(CAMERA, object_points, params[:3], params[3:])
        return scale * (projected - points).reshape(-1)

    def jacobian(params):
        return scale[:, None] * reprojection(CAMERA, object_points, params[:3], params[3:])[1]

    return residuals, jacobian


def _least_squares_refinement(points: np.ndarray, start: np.ndarray):
    """The refinement as scipy's least_squares(method="lm") states it (before round 10)."""
    from scipy.optimize import least_squares

    residuals, jacobian = _weighted_cost(points)
    return least_squares(
        residuals, start, jac=jacobian, method="lm", xtol=1e-12, ftol=1e-12, x_scale="jac"
    )


def test_weighted_refinement_is_least_squares_lm():
    """least_squares(method="lm") with the solver's settings: the same pose, from good starts and
    from far ones (which take many steps, some rejected).

    A start that exhausts MINPACK's 600 evaluations without converging is left out: that walk
    is chaotic, and its end depends on the CPU's SIMD paths (it differed on the CI machine).
    Converged runs agree to the bit here; 1e-10 leaves room for another CPU's last bits.
    """
    rng = np.random.default_rng(11)
    converged = 0
    for trajectory in ("circle", "figure_eight"):
        rotations, positions = _poses(trajectory)
        for frame in range(0, 40, 5):
            points = _noisy_points(rng, rotations[frame], positions[frame])
            for start in (_sqpnp(points), _sqpnp(points) + rng.normal(0.0, 0.5, 6)):
                reference = _least_squares_refinement(points, start)
                if reference.status == 0:
                    continue
                converged += 1
                kept = start.copy()
                ours = weighted_refinement(CAMERA, SCENE.object_points(), points, start, WEIGHTS)
                assert start.tobytes() == kept.tobytes()  # the start is not written to
                np.testing.assert_allclose(ours, reference.x, rtol=0, atol=1e-10)
    assert converged >= 30


def test_weighted_refinement_refuses_too_few_points():
    points = SCENE.object_points()[:2]
    with pytest.raises(InputError, match="at least 3 points, got 2"):
        weighted_refinement(CAMERA, points, np.zeros((2, 2)), np.zeros(6), np.ones(2))
