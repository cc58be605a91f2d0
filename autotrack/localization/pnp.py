"""PnP: the pose solvers (SQPnP + Levenberg-Marquardt, P3P), the predicted position uncertainty
and the correspondence search that tells which box is which landmark (Faessler et al., ICRA 2014).

Pure functions over OpenCV's world-to-camera (rvec, tvec); the Localizer chooses among them.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from autotrack.errors import InputError
from autotrack.localization.camera import CameraIntrinsics, camera_pose_from_pnp
from autotrack.localization.scene import Scene

Box = tuple[float, float, float, float]

_LM_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-12)


@dataclass(frozen=True)
class Fit:
    """A solved pose (world-to-camera rvec, tvec) with its per-landmark reprojection errors."""

    rvec: np.ndarray
    tvec: np.ndarray
    ids: tuple[str, ...]
    errors: np.ndarray
    rms: float


def reprojection(
    camera: CameraIntrinsics, object_points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Projections (n, 2) and their Jacobian (2n, 6) w.r.t. (rvec, tvec)."""
    projected, jacobian = cv2.projectPoints(
        object_points.reshape(-1, 1, 3), rvec, tvec, camera.matrix(), camera.distortion_array()
    )
    return projected.reshape(-1, 2), jacobian[:, :6]


def refine_pose(
    camera: CameraIntrinsics,
    object_points: np.ndarray,
    image_points: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
    weights: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg-Marquardt on the reprojection error, each point's residual scaled by sqrt(weight).

    Equal weights use OpenCV's solvePnPRefineLM; unequal ones the same cost with per-point
    weights (`weighted_refinement`).
    """
    rvec = np.asarray(rvec, dtype=np.float64).reshape(3, 1).copy()
    tvec = np.asarray(tvec, dtype=np.float64).reshape(3, 1).copy()
    if weights is None or _all_close(np.asarray(weights, dtype=np.float64)):
        rvec, tvec = cv2.solvePnPRefineLM(
            object_points.reshape(-1, 1, 3),
            image_points.reshape(-1, 1, 2),
            camera.matrix(),
            camera.distortion_array(),
            rvec,
            tvec,
            criteria=_LM_CRITERIA,
        )
        return rvec.reshape(3), tvec.reshape(3)
    start = np.concatenate([rvec.reshape(3), tvec.reshape(3)])
    solution = weighted_refinement(camera, object_points, image_points, start, weights)
    return solution[:3], solution[3:]


def _all_close(weights: np.ndarray) -> bool:
    """np.allclose(weights, weights[0]) (its default tolerances) without its overhead."""
    return bool(np.all(np.abs(weights - weights[0]) <= 1e-8 + 1e-5 * abs(weights[0])))


def weighted_refinement(
    camera: CameraIntrinsics,
    object_points: np.ndarray,
    image_points: np.ndarray,
    start: np.ndarray,
    weights: np.ndarray,
) -> np.ndarray:
    """(rvec | tvec) minimising sum_i w_i |project(X_i) - x_i|^2 from `start`: MINPACK's
    Levenberg-Marquardt on OpenCV's analytic Jacobian, what solvePnPRefineLM does for equal
    weights.

    `scipy.optimize.least_squares(method="lm", xtol=1e-12, ftol=1e-12, x_scale="jac")` (MINPACK's
    lmder: gtol 1e-8, at most 100 n evaluations), called as `scipy.optimize.leastsq`, the same
    lmder call with those settings (the same pose to the bit, tests/test_pnp_refine.py) without
    least_squares' wrapping of the functions (~0.1 ms a call). One projection serves both the
    residuals and the Jacobian at a point (MINPACK asks for the Jacobian at the point it has just
    evaluated).
    """
    scale = np.repeat(np.sqrt(np.asarray(weights, dtype=np.float64)), 2)
    projection = _CachedProjection(camera, object_points)

    def residuals(params: np.ndarray) -> np.ndarray:
        projected, _ = projection(params)
        return scale * (projected - image_points).reshape(-1)

    def jacobian(params: np.ndarray) -> np.ndarray:
        _, jac = projection(params)
        return scale[:, None] * jac

    start = np.asarray(start, dtype=np.float64).flatten()  # a copy: MINPACK works in place
    if residuals(start).size < start.size:
        raise InputError(f"a pose refinement needs at least 3 points, got {len(image_points)}")
    from scipy.optimize import leastsq  # ~0.45 s to import: only when weights differ

    solution = leastsq(
        residuals, start, Dfun=jacobian, xtol=1e-12, ftol=1e-12, gtol=1e-8, maxfev=100 * start.size
    )[0]
    return np.asarray(solution, dtype=np.float64)


class _CachedProjection:
    """`reprojection` at the last point asked for, kept for the next call at the same point."""

    def __init__(self, camera: CameraIntrinsics, object_points: np.ndarray) -> None:
        self._camera = camera
        self._object_points = object_points
        self._key: bytes | None = None
        self._value: tuple[np.ndarray, np.ndarray] = (np.empty(0), np.empty(0))

    def __call__(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = params.tobytes()
        if key != self._key:
            self._value = reprojection(self._camera, self._object_points, params[:3], params[3:])
            self._key = key
        return self._value


def solve_pose(
    camera: CameraIntrinsics,
    object_points: np.ndarray,
    image_points: np.ndarray,
    weights: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Pose (rvec, tvec, world-to-camera) from four or more correspondences: SQPnP, then LM."""
    ok, rvec, tvec = cv2.solvePnP(
        object_points.reshape(-1, 1, 3),
        image_points.reshape(-1, 1, 2),
        camera.matrix(),
        camera.distortion_array(),
        flags=cv2.SOLVEPNP_SQPNP,
    )
    if not ok:
        raise InputError("SQPnP found no pose for these correspondences")
    return refine_pose(camera, object_points, image_points, rvec, tvec, weights)


def p3p_solutions(
    camera: CameraIntrinsics, object_points: np.ndarray, image_points: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray]]:
    """All P3P poses (rvec, tvec) for exactly three correspondences (up to four)."""
    count, rvecs, tvecs = cv2.solveP3P(
        np.ascontiguousarray(object_points, dtype=np.float64).reshape(3, 1, 3),
        np.ascontiguousarray(image_points, dtype=np.float64).reshape(3, 1, 2),
        camera.matrix(),
        camera.distortion_array(),
        flags=cv2.SOLVEPNP_AP3P,
    )
    return [(rvecs[i].reshape(3), tvecs[i].reshape(3)) for i in range(count)]


def position_std(
    camera: CameraIntrinsics,
    object_points: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
    pixel_noise_px: float,
    weights: np.ndarray | None = None,
) -> float:
    """Predicted 1-sigma camera-centre uncertainty (metres) for `pixel_noise_px` image noise.

    First-order propagation: Cov(rvec, tvec) = sigma^2 (J^T W J)^-1, then through C = -R^T t.
    Infinite when the geometry does not constrain the pose.
    """
    _, jac = reprojection(camera, object_points, rvec, tvec)
    w = np.ones(len(object_points)) if weights is None else np.asarray(weights, dtype=np.float64)
    information = jac.T @ (np.repeat(w, 2)[:, None] * jac)
    try:
        covariance = pixel_noise_px**2 * np.linalg.inv(information)
    except np.linalg.LinAlgError:
        return math.inf
    if np.linalg.cond(information) > 1e14:
        return math.inf
    # d(centre)/d(rvec) by central differences, d(centre)/d(tvec) = -R^T.
    gradient = np.zeros((3, 6))
    step = 1e-6
    for k in range(3):
        delta = np.zeros(3)
        delta[k] = step
        _, plus = camera_pose_from_pnp(rvec + delta, tvec)
        _, minus = camera_pose_from_pnp(rvec - delta, tvec)
        gradient[:, k] = (plus - minus) / (2 * step)
    rotation_cw, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    gradient[:, 3:] = -rotation_cw.T
    centre_covariance = gradient @ covariance @ gradient.T
    return float(math.sqrt(max(np.trace(centre_covariance), 0.0)))


def fit_pose(
    camera: CameraIntrinsics,
    ids: tuple[str, ...],
    object_points: np.ndarray,
    image_points: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
) -> Fit:
    projected, _ = reprojection(camera, object_points, rvec, tvec)
    errors = np.linalg.norm(projected - image_points, axis=1)
    return Fit(rvec, tvec, ids, errors, float(np.sqrt(np.mean(errors**2))))


@dataclass(frozen=True)
class Correspondence:
    """The best assignment of image points to landmarks, with how well it fits and how close
    the next best comes (see `rank_correspondences`)."""

    assignment: dict[str, int]
    """Landmark id -> row of the image points."""
    errors: dict[str, float]
    """Landmark id -> reprojection error (px) of its point under the refined pose."""
    rms: float
    """RMS of `errors` (px)."""
    runner_up_rms: float
    """RMS (px, after refinement) of the best assignment that differs from `assignment`
    (inf when there is none)."""
    max_error_px: float
    """The RMS above which an assignment is implausible."""

    @property
    def plausible(self) -> bool:
        """The best assignment reprojects within `max_error_px`."""
        return self.rms <= self.max_error_px

    @property
    def ambiguous(self) -> bool:
        """Another assignment also reprojects within `max_error_px`: the layout (or the boxes)
        cannot tell them apart."""
        return self.runner_up_rms <= self.max_error_px


def _refined_fit(
    scene: Scene, chosen: tuple[str, ...], points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray
) -> Fit:
    object_points = scene.object_points(chosen)
    rvec, tvec = refine_pose(scene.camera, object_points, points, rvec, tvec)
    return fit_pose(scene.camera, chosen, object_points, points, rvec, tvec)


def rank_correspondences(
    points_2d: np.ndarray,
    scene: Scene,
    *,
    landmark_ids: Sequence[str] | None = None,
    max_error_px: float = 5.0,
) -> Correspondence | None:
    """Which image point is which landmark, when the assignment is unknown (Faessler et al.).

    For every assignment of the image points to distinct landmarks (of `landmark_ids`, default
    all the scene's): P3P on the first three, reproject the remaining landmarks and keep the
    P3P solution that fits them best. The two best assignments are refined on all points; the
    best is returned with its per-landmark errors and the runner-up's RMS. None when no
    assignment puts the landmarks in front of the camera, or the image triangle is degenerate.
    """
    points = np.asarray(points_2d, dtype=np.float64).reshape(-1, 2)
    candidates = tuple(scene.landmark_ids if landmark_ids is None else landmark_ids)
    if len(points) < 4:
        raise InputError(
            f"the correspondence search needs at least 4 image points, got {len(points)}"
        )
    if len(points) > len(candidates):
        raise InputError(
            f"{len(points)} image points but only {len(candidates)} landmarks to assign them to"
        )
    camera = scene.camera
    ranked: list[tuple[float, tuple[str, ...], np.ndarray, np.ndarray]] = []
    for chosen in itertools.permutations(candidates, len(points)):
        object_points = scene.object_points(chosen)
        try:
            solutions = p3p_solutions(camera, object_points[:3], points[:3])
        except cv2.error:  # degenerate image triangle
            return None
        best: tuple[float, tuple[str, ...], np.ndarray, np.ndarray] | None = None
        for rvec, tvec in solutions:
            if not in_front(object_points, rvec, tvec, 0.0):
                continue
            projected, _ = reprojection(camera, object_points[3:], rvec, tvec)
            error = float(np.sqrt(np.mean(np.sum((projected - points[3:]) ** 2, axis=1))))
            if best is None or error < best[0]:
                best = (error, chosen, rvec, tvec)
        if best is not None:
            ranked.append(best)
    if not ranked:
        return None
    ranked.sort(key=lambda entry: entry[0])
    fits = sorted(
        (_refined_fit(scene, chosen, points, rvec, tvec) for _, chosen, rvec, tvec in ranked[:2]),
        key=lambda fit: fit.rms,
    )
    best_fit = fits[0]
    return Correspondence(
        assignment={landmark_id: row for row, landmark_id in enumerate(best_fit.ids)},
        errors={lid: float(e) for lid, e in zip(best_fit.ids, best_fit.errors, strict=True)},
        rms=best_fit.rms,
        runner_up_rms=fits[1].rms if len(fits) > 1 else math.inf,
        max_error_px=max_error_px,
    )


def search_correspondences(
    points_2d: np.ndarray,
    scene: Scene,
    *,
    max_error_px: float = 5.0,
) -> dict[str, int]:
    """Landmark id -> row of `points_2d` by `rank_correspondences`, or an empty dict when no
    assignment reprojects within `max_error_px` (RMS over all points after refinement). A
    symmetric layout has several equally good answers (scene_warnings flags it); the best
    found is returned."""
    found = rank_correspondences(points_2d, scene, max_error_px=max_error_px)
    if found is None or not found.plausible:
        return {}
    return found.assignment


def in_front(object_points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, min_depth: float):
    rotation_cw, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    depths = (object_points @ rotation_cw.T + np.asarray(tvec).reshape(1, 3))[:, 2]
    return bool(np.all(depths > min_depth))


def box_centre(box: Sequence[float]) -> tuple[float, float]:
    """Centre (u, v) of an (x, y, w, h) box, 0-based pixels."""
    x, y, w, h = (float(v) for v in box)
    return (x + w / 2.0, y + h / 2.0)


def assign_boxes(
    boxes: Sequence[Box], scene: Scene, *, max_error_px: float = 5.0
) -> dict[str, Box]:
    """Landmark id -> box for boxes given without their landmark (correspondence search)."""
    centres = np.array([box_centre(b) for b in boxes])
    assignment = search_correspondences(centres, scene, max_error_px=max_error_px)
    if not assignment:
        raise InputError(
            "cannot tell which box is which landmark: no assignment of the box centres to the "
            "scene's landmarks reprojects within "
            f"{max_error_px:g} px; check the boxes and the scene, or give boxes.json as "
            "{landmark id: box}"
        )
    return {landmark_id: tuple(boxes[row]) for landmark_id, row in assignment.items()}


def boxes_by_landmark(boxes: Mapping[str, Box] | Sequence[Box], scene: Scene) -> dict[str, Box]:
    """Landmark id -> box from boxes.json's two forms: a mapping is checked against the scene's
    landmarks, a list is assigned by the correspondence search (`assign_boxes`)."""
    if isinstance(boxes, Mapping):
        for landmark_id in boxes:
            scene.landmark(str(landmark_id))  # SceneError naming the scene's landmarks
        return {str(k): tuple(float(v) for v in box) for k, box in boxes.items()}
    return assign_boxes([tuple(float(v) for v in box) for box in boxes], scene)
