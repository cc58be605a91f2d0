"""Localisation by tracking (paper section 4): camera pose from tracked landmarks of known position.

Four (or more) landmarks with surveyed 3-D positions are tracked by AutoTrack; each box centre is
taken as the landmark's image point, and the camera pose follows from a PnP solve, as in Faessler
et al. (ICRA 2014) with tracked objects in place of infrared LEDs:

1. choose the landmarks to use: drop those the tracker reports as unreliable (low peak score),
   down-weight those whose filter update was stopped (aberrant frame);
2. solve: SQPnP on four or more points, refined by Levenberg-Marquardt on the (weighted)
   reprojection error; P3P on three points, the solution nearest the previous pose;
3. check: reprojection RMS, per-landmark outliers (a drifting tracker is dropped and the pose
   kept from the other three), conditioning (predicted position spread), points in front of the
   camera, and continuity with the previous trusted pose. A frame that fails is reported invalid
   with the reason instead of a wrong pose.

Poses are camera-to-world: `rotation` maps camera axes (OpenCV: x right, y down, z forward) to
world axes, `position` is the camera centre in world metres.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from autotrack.errors import BoxError, InputError
from autotrack.params import TrackerParams
from autotrack.reacquire import LandmarkKeeper, ReacquireParams
from autotrack.refine import PointRefiner, RefineParams, to_grey
from autotrack.result import TrackResult
from autotrack.scene import CameraIntrinsics, Scene

Box = tuple[float, float, float, float]

_LM_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-12)


@dataclass(frozen=True)
class LocalizerParams:
    """Thresholds of the pose solver. Pixel figures are in the scene camera's image."""

    max_rms_error_px: float = 3.0
    """A pose whose RMS reprojection error over the landmarks used exceeds this is not trusted."""
    max_landmark_error_px: float = 5.0
    """A landmark reprojecting farther than this from its box centre is an outlier: the pose is
    solved again without it."""
    min_peak_score: float = 0.0
    """Landmarks whose tracker peak score is below this are dropped (0 keeps all; NaN, as in the
    first frame, always passes). Peak values depend on the target; see min_relative_peak."""
    min_relative_peak: float = 0.3
    """A landmark whose peak score falls below this fraction of its own median peak (over its
    last `peak_history_frames` trusted frames) is dropped: the tracker has lost confidence
    (occlusion, drift). 0 disables."""
    peak_history_frames: int = 30
    """Trusted frames per landmark the median peak is taken over (at least 5 are needed)."""
    aberrant_weight: float = 0.25
    """Weight of a landmark whose tracker flagged the frame aberrant (1 = full, 0 = drop)."""
    max_translation_per_frame_m: float = 0.5
    """Largest plausible camera movement between consecutive frames (metres; 0.5 = 5 m/s at
    10 fps). A pose jumping farther from the previous trusted pose is invalid."""
    max_rotation_per_frame_deg: float = 30.0
    """Largest plausible camera rotation between consecutive frames (degrees)."""
    three_point_translation_per_frame_m: float = 0.15
    """Tighter movement bound for poses from three landmarks, which have no redundancy to catch
    a wrong P3P solution or a drifting tracker (metres per frame)."""
    prior_max_age_frames: int = 10
    """The previous trusted pose serves as prior (continuity check, P3P choice) for this many
    frames; after that a four-landmark pose re-initialises on its own."""
    pixel_noise_px: float = 1.0
    """Assumed image-point noise for the predicted position uncertainty (pixels, 1 sigma)."""
    max_position_std_m: float = 0.10
    """A pose whose predicted position uncertainty (from the solve's Jacobian and
    `pixel_noise_px`) exceeds this is ill-conditioned and not trusted (metres)."""
    min_depth_m: float = 0.05
    """Every landmark used must lie at least this far in front of the camera (metres)."""


@dataclass(frozen=True)
class PoseEstimate:
    """Camera pose of one frame, or the reason there is none to trust."""

    frame_index: int
    """0-based index of the frame."""
    valid: bool
    """True when the pose passed every check; False poses carry NaN rotation and position."""
    rotation: np.ndarray
    """Camera-to-world rotation (3x3): columns are the camera axes in world coordinates."""
    position: np.ndarray
    """Camera centre in world coordinates (3,), metres."""
    reprojection_errors: dict[str, float]
    """Distance (px) between each landmark's reprojection and its box centre, NaN if unused."""
    used_landmarks: tuple[str, ...]
    """Landmarks the pose was solved from."""
    reason: str = ""
    """Empty when valid, else why the frame is not trusted."""
    rms_error_px: float = math.nan
    """RMS reprojection error over the landmarks used (px)."""
    position_std_m: float = math.nan
    """Predicted 1-sigma uncertainty of the camera position (metres, all axes together)."""
    excluded_landmarks: dict[str, str] = field(default_factory=dict)
    """Landmarks left out of the solve and why (lost, low peak score, aberrant, outlier)."""

    def quaternion_xyzw(self) -> np.ndarray:
        """The rotation as a unit quaternion (qx, qy, qz, qw), TUM order; NaN when invalid."""
        if not np.all(np.isfinite(self.rotation)):
            return np.full(4, np.nan)
        return Rotation.from_matrix(self.rotation).as_quat(canonical=True)


@dataclass(frozen=True)
class LocalizationFrame:
    """Everything the pipeline produced for one frame."""

    frame_index: int
    tracks: dict[str, TrackResult]
    """Tracker output per landmark id."""
    image_points: dict[str, tuple[float, float]]
    """Point per landmark id given to the solver: the box centre, or the refined point when
    refinement is on and accepted."""
    pose: PoseEstimate
    box_centres: dict[str, tuple[float, float]] = field(default_factory=dict)
    """The trackers' box centres (the raw points; equal to image_points without refinement)."""
    refined: dict[str, bool] = field(default_factory=dict)
    """Per landmark, whether the refined point replaced the box centre this frame."""
    events: dict[str, str] = field(default_factory=dict)
    """Landmark id -> what happened to it this frame beyond tracking ("out of view",
    "re-acquired at (u, v), match m")."""


@dataclass(frozen=True)
class _Fit:
    rvec: np.ndarray
    tvec: np.ndarray
    ids: tuple[str, ...]
    errors: np.ndarray
    rms: float


# ---------------------------------------------------------------------------------------------
# Pure geometry


def camera_pose_from_pnp(rvec: np.ndarray, tvec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rotation camera-to-world, camera centre) from OpenCV's world-to-camera rvec, tvec."""
    rotation_cw, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    # x_cam = R_cw x_world + t  =>  camera centre C = -R_cw^T t, R_wc = R_cw^T
    centre = -rotation_cw.T @ np.asarray(tvec, dtype=np.float64).reshape(3)
    return rotation_cw.T, centre


def pnp_from_camera_pose(
    rotation: np.ndarray, position: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's (rvec, tvec) from a camera-to-world rotation and camera centre."""
    rotation_cw = np.asarray(rotation, dtype=np.float64).T
    rvec, _ = cv2.Rodrigues(rotation_cw)
    tvec = -rotation_cw @ np.asarray(position, dtype=np.float64).reshape(3)
    return rvec.reshape(3), tvec


def project_points(
    camera: CameraIntrinsics, points_world: np.ndarray, rotation: np.ndarray, position: np.ndarray
) -> np.ndarray:
    """Pixel coordinates (n, 2) of world points seen by a camera at (rotation, position)."""
    rvec, tvec = pnp_from_camera_pose(rotation, position)
    projected, _ = cv2.projectPoints(
        np.asarray(points_world, dtype=np.float64).reshape(-1, 1, 3),
        rvec,
        tvec,
        camera.matrix(),
        camera.distortion_array(),
    )
    return projected.reshape(-1, 2)


def rotation_angle_deg(rotation_a: np.ndarray, rotation_b: np.ndarray) -> float:
    """Angle (degrees) of the rotation taking `rotation_a` to `rotation_b`."""
    cosine = (np.trace(rotation_a.T @ rotation_b) - 1.0) / 2.0
    return math.degrees(math.acos(float(np.clip(cosine, -1.0, 1.0))))


def _reprojection(
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

    Equal weights use OpenCV's solvePnPRefineLM; unequal ones the same cost with per-point weights.
    """
    rvec = np.asarray(rvec, dtype=np.float64).reshape(3, 1).copy()
    tvec = np.asarray(tvec, dtype=np.float64).reshape(3, 1).copy()
    if weights is None or np.allclose(weights, weights[0]):
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
    scale = np.repeat(np.sqrt(np.asarray(weights, dtype=np.float64)), 2)

    def residuals(params: np.ndarray) -> np.ndarray:
        projected, _ = _reprojection(camera, object_points, params[:3], params[3:])
        return scale * (projected - image_points).reshape(-1)

    def jacobian(params: np.ndarray) -> np.ndarray:
        _, jac = _reprojection(camera, object_points, params[:3], params[3:])
        return scale[:, None] * jac

    start = np.concatenate([rvec.reshape(3), tvec.reshape(3)])
    solution = least_squares(residuals, start, jac=jacobian, method="lm", xtol=1e-12, ftol=1e-12)
    return solution.x[:3], solution.x[3:]


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
    _, jac = _reprojection(camera, object_points, rvec, tvec)
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


def _fit(
    camera: CameraIntrinsics,
    ids: tuple[str, ...],
    object_points: np.ndarray,
    image_points: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
) -> _Fit:
    projected, _ = _reprojection(camera, object_points, rvec, tvec)
    errors = np.linalg.norm(projected - image_points, axis=1)
    return _Fit(rvec, tvec, ids, errors, float(np.sqrt(np.mean(errors**2))))


def search_correspondences(
    points_2d: np.ndarray,
    scene: Scene,
    *,
    max_error_px: float = 5.0,
) -> dict[str, int]:
    """Which image point is which landmark, when the assignment is unknown (Faessler et al.).

    For every assignment of the image points to distinct landmarks: P3P on the first three,
    reproject the remaining landmarks and keep the P3P solution that fits them best; the
    assignment with the smallest error wins, then its pose is refined on all points. Returns
    landmark id -> row of `points_2d`, or an empty dict when no assignment reprojects within
    `max_error_px` (RMS over all points after refinement). A symmetric layout has several
    equally good answers (scene_warnings flags it); the first found is returned.
    """
    points = np.asarray(points_2d, dtype=np.float64).reshape(-1, 2)
    if len(points) < 4:
        raise InputError(
            f"the correspondence search needs at least 4 image points, got {len(points)}"
        )
    if len(points) > len(scene.landmarks):
        raise InputError(
            f"{len(points)} image points but the scene has only {len(scene.landmarks)} landmarks"
        )
    camera = scene.camera
    best: tuple[float, tuple[str, ...], np.ndarray, np.ndarray] | None = None
    for chosen in itertools.permutations(scene.landmark_ids, len(points)):
        object_points = scene.object_points(chosen)
        try:
            solutions = p3p_solutions(camera, object_points[:3], points[:3])
        except cv2.error:  # degenerate image triangle
            return {}
        for rvec, tvec in solutions:
            if not _in_front(object_points, rvec, tvec, 0.0):
                continue
            projected, _ = _reprojection(camera, object_points[3:], rvec, tvec)
            error = float(np.sqrt(np.mean(np.sum((projected - points[3:]) ** 2, axis=1))))
            if best is None or error < best[0]:
                best = (error, chosen, rvec, tvec)
    if best is None:
        return {}
    _, chosen, rvec, tvec = best
    object_points = scene.object_points(chosen)
    rvec, tvec = refine_pose(camera, object_points, points, rvec, tvec)
    fit = _fit(camera, chosen, object_points, points, rvec, tvec)
    if fit.rms > max_error_px:
        return {}
    return {landmark_id: row for row, landmark_id in enumerate(chosen)}


def _describe(excluded: Mapping[str, str]) -> str:
    return "; ".join(f"{landmark_id} {why}" for landmark_id, why in excluded.items())


def _in_front(object_points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, min_depth: float):
    rotation_cw, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    depths = (object_points @ rotation_cw.T + np.asarray(tvec).reshape(1, 3))[:, 2]
    return bool(np.all(depths > min_depth))


# ---------------------------------------------------------------------------------------------
# The stateful per-frame solver


@dataclass
class _Prior:
    frame_index: int
    rotation: np.ndarray
    position: np.ndarray


@dataclass
class Localizer:
    """Per-frame camera pose from landmark image points, with the previous trusted pose as prior."""

    scene: Scene
    params: LocalizerParams = field(default_factory=LocalizerParams)
    _prior: _Prior | None = field(default=None, init=False, repr=False)
    _peaks: dict[str, deque[float]] = field(default_factory=dict, init=False, repr=False)

    def reset(self) -> None:
        """Forget the previous pose and the peak-score history (call when frames are not
        consecutive any more or the trackers were restarted)."""
        self._prior = None
        self._peaks.clear()

    def forget_landmark(self, landmark_id: str) -> None:
        """Forget a landmark's peak-score history (its tracker was restarted)."""
        self._peaks.pop(landmark_id, None)

    def estimate(
        self,
        frame_index: int,
        points: Mapping[str, tuple[float, float]],
        confidences: Mapping[str, float] | None = None,
        aberrant: Mapping[str, bool] | None = None,
        landmark_weights: Mapping[str, float] | None = None,
    ) -> PoseEstimate:
        """Pose for one frame from landmark id -> image point (u, v), 0-based pixels.

        `confidences` are tracker peak scores, `aberrant` the tracker's aberrance flags,
        `landmark_weights` per-landmark weights in the refinement (default 1, multiplied with the
        aberrant weight); all optional. Unknown ids raise SceneError; missing or non-finite
        points count as lost.
        """
        params = self.params
        confidences = confidences or {}
        aberrant = aberrant or {}
        for landmark_id in points:
            self.scene.landmark(landmark_id)
        excluded: dict[str, str] = {}
        usable: list[str] = []
        weights: list[float] = []
        for landmark_id in self.scene.landmark_ids:
            point = points.get(landmark_id)
            if point is None or not np.all(np.isfinite(point)):
                excluded[landmark_id] = "lost"
                continue
            score = confidences.get(landmark_id, math.nan)
            if math.isfinite(score) and score < params.min_peak_score:
                excluded[landmark_id] = f"peak {score:.3g} < {params.min_peak_score:g}"
                continue
            typical = self._typical_peak(landmark_id)
            if math.isfinite(score) and score < params.min_relative_peak * typical:
                excluded[landmark_id] = (
                    f"peak {score:.3g} < {params.min_relative_peak:g} x its median {typical:.3g}"
                )
                continue
            weight = params.aberrant_weight if aberrant.get(landmark_id, False) else 1.0
            weight *= (landmark_weights or {}).get(landmark_id, 1.0)
            if weight <= 0.0:
                excluded[landmark_id] = "aberrant"
                continue
            usable.append(landmark_id)
            weights.append(weight)
        prior = self._current_prior(frame_index)
        if len(usable) < 3:
            detail = _describe(excluded)
            return self._invalid(
                frame_index, f"only {len(usable)} usable landmark(s) ({detail})", excluded
            )
        ids = tuple(usable)
        image_points = np.array([points[i] for i in ids], dtype=np.float64).reshape(-1, 2)
        weight_array = np.array(weights)
        try:
            if len(ids) >= 4:
                fit, reason = self._solve_redundant(ids, image_points, weight_array, prior)
            else:
                fit, reason = self._solve_three(ids, image_points, prior)
        except (cv2.error, np.linalg.LinAlgError, InputError):
            # OpenCV asserts on coincident or collinear image points: no pose, not a crash.
            fit, reason = None, "degenerate image points (coincident or collinear): no PnP solution"
        if fit is None:
            if excluded:
                reason = f"{reason} ({_describe(excluded)})"
            return self._invalid(frame_index, reason, excluded)
        pose = self._checked(frame_index, fit, weight_array, ids, prior, excluded, image_points)
        if pose.valid:
            for landmark_id in pose.used_landmarks:
                score = confidences.get(landmark_id, math.nan)
                if math.isfinite(score):
                    history = self._peaks.setdefault(
                        landmark_id, deque(maxlen=params.peak_history_frames)
                    )
                    history.append(score)
        return pose

    def _typical_peak(self, landmark_id: str) -> float:
        """Median peak score of a landmark over its recent trusted frames (NaN: too few yet)."""
        history = self._peaks.get(landmark_id)
        if history is None or len(history) < 5:
            return math.nan
        return float(np.median(history))

    # -- solving ---------------------------------------------------------------------------

    def _solve_redundant(
        self,
        ids: tuple[str, ...],
        image_points: np.ndarray,
        weights: np.ndarray,
        prior: _Prior | None,
    ) -> tuple[_Fit | None, str]:
        """Four or more points: fit all, then drop outliers one at a time while >= 4 remain;
        with exactly four inconsistent points fall back to the three nearest the prior."""
        camera = self.scene.camera
        keep = list(range(len(ids)))
        while True:
            sub_ids = tuple(ids[k] for k in keep)
            object_points = self.scene.object_points(sub_ids)
            rvec, tvec = solve_pose(camera, object_points, image_points[keep], weights[keep])
            fit = _fit(camera, sub_ids, object_points, image_points[keep], rvec, tvec)
            if self._consistent(fit):
                return fit, ""
            if len(keep) == 4:
                break
            keep.pop(int(np.argmax(fit.errors)))
        if prior is None:
            worst = sub_ids[int(np.argmax(fit.errors))]
            return None, (
                f"landmarks disagree (worst {worst}: {fit.errors.max():.1f} px, RMS "
                f"{fit.rms:.1f} px) and there is no recent pose to tell which one is off"
            )
        candidates = []
        for left_out in range(4):
            triple = [keep[k] for k in range(4) if k != left_out]
            candidates += self._p3p_fits(tuple(ids[k] for k in triple), image_points[triple])
        chosen = self._nearest_to_prior(candidates, prior)
        if chosen is None:
            return None, "landmarks disagree and no three of them give a pose near the previous one"
        return chosen, ""

    def _solve_three(
        self, ids: tuple[str, ...], image_points: np.ndarray, prior: _Prior | None
    ) -> tuple[_Fit | None, str]:
        if prior is None:
            return None, (
                f"only three landmarks ({', '.join(ids)}) and no recent pose to choose among the "
                "P3P solutions"
            )
        chosen = self._nearest_to_prior(self._p3p_fits(ids, image_points), prior)
        if chosen is None:
            return None, f"no P3P solution from {', '.join(ids)} is in front of the camera"
        return chosen, ""

    def _p3p_fits(self, ids: tuple[str, ...], image_points: np.ndarray) -> list[_Fit]:
        camera = self.scene.camera
        object_points = self.scene.object_points(ids)
        fits = []
        for rvec, tvec in p3p_solutions(camera, object_points, image_points):
            if _in_front(object_points, rvec, tvec, self.params.min_depth_m):
                rvec, tvec = refine_pose(camera, object_points, image_points, rvec, tvec)
                fits.append(_fit(camera, ids, object_points, image_points, rvec, tvec))
        return fits

    def _nearest_to_prior(self, fits: list[_Fit], prior: _Prior) -> _Fit | None:
        """The fit closest to the prior, distance in units of the per-frame motion bounds."""
        params = self.params
        best: tuple[float, _Fit] | None = None
        for fit in fits:
            rotation, position = camera_pose_from_pnp(fit.rvec, fit.tvec)
            distance = float(np.linalg.norm(position - prior.position))
            angle = rotation_angle_deg(prior.rotation, rotation)
            score = (
                distance / params.max_translation_per_frame_m
                + angle / params.max_rotation_per_frame_deg
            )
            if best is None or score < best[0]:
                best = (score, fit)
        return None if best is None else best[1]

    def _consistent(self, fit: _Fit) -> bool:
        return (
            fit.rms <= self.params.max_rms_error_px
            and float(fit.errors.max()) <= self.params.max_landmark_error_px
        )

    # -- checking --------------------------------------------------------------------------

    def _checked(
        self,
        frame_index: int,
        fit: _Fit,
        weights_all: np.ndarray,
        ids_all: tuple[str, ...],
        prior: _Prior | None,
        excluded: dict[str, str],
        points_all: np.ndarray,
    ) -> PoseEstimate:
        params = self.params
        camera = self.scene.camera
        rotation, position = camera_pose_from_pnp(fit.rvec, fit.tvec)
        excluded = dict(excluded)
        left_out = [i for i in ids_all if i not in fit.ids]
        if left_out:
            rows = [ids_all.index(i) for i in left_out]
            projected, _ = _reprojection(
                camera, self.scene.object_points(left_out), fit.rvec, fit.tvec
            )
            for landmark_id, row, point in zip(left_out, rows, projected, strict=True):
                distance = float(np.linalg.norm(point - points_all[row]))
                excluded[landmark_id] = f"outlier: {distance:.1f} px from the others' pose"
        errors = {landmark_id: math.nan for landmark_id in self.scene.landmark_ids}
        for landmark_id, error in zip(fit.ids, fit.errors, strict=True):
            errors[landmark_id] = float(error)
        weights = np.array([weights_all[ids_all.index(i)] for i in fit.ids])
        object_points = self.scene.object_points(fit.ids)
        std = position_std(
            camera, object_points, fit.rvec, fit.tvec, params.pixel_noise_px, weights
        )
        reasons = []
        if not _in_front(object_points, fit.rvec, fit.tvec, params.min_depth_m):
            reasons.append("a landmark would be behind the camera")
        if fit.rms > params.max_rms_error_px:
            reasons.append(f"RMS reprojection error {fit.rms:.1f} px > {params.max_rms_error_px:g}")
        if std > params.max_position_std_m:
            reasons.append(
                f"ill-conditioned geometry (position uncertainty {std * 100:.0f} cm > "
                f"{params.max_position_std_m * 100:.0f} cm)"
            )
        if prior is not None:
            age = frame_index - prior.frame_index
            per_frame = (
                params.three_point_translation_per_frame_m
                if len(fit.ids) == 3
                else params.max_translation_per_frame_m
            )
            jump = float(np.linalg.norm(position - prior.position))
            turn = rotation_angle_deg(prior.rotation, rotation)
            if jump > per_frame * max(age, 1):
                reasons.append(
                    f"jump of {jump:.2f} m from the pose of frame {prior.frame_index} "
                    f"(limit {per_frame:g} m per frame)"
                )
            if turn > params.max_rotation_per_frame_deg * max(age, 1):
                reasons.append(
                    f"turn of {turn:.0f} deg from the pose of frame {prior.frame_index} "
                    f"(limit {params.max_rotation_per_frame_deg:g} deg per frame)"
                )
        elif len(fit.ids) == 3:
            reasons.append("three-landmark pose without a recent pose to check it against")
        if reasons:
            return PoseEstimate(
                frame_index=frame_index,
                valid=False,
                rotation=np.full((3, 3), np.nan),
                position=np.full(3, np.nan),
                reprojection_errors=errors,
                used_landmarks=fit.ids,
                reason="; ".join(reasons),
                rms_error_px=fit.rms,
                position_std_m=std,
                excluded_landmarks=excluded,
            )
        self._prior = _Prior(frame_index, rotation, position)
        return PoseEstimate(
            frame_index=frame_index,
            valid=True,
            rotation=rotation,
            position=position,
            reprojection_errors=errors,
            used_landmarks=fit.ids,
            reason="",
            rms_error_px=fit.rms,
            position_std_m=std,
            excluded_landmarks=excluded,
        )

    def _current_prior(self, frame_index: int) -> _Prior | None:
        prior = self._prior
        if prior is None:
            return None
        age = frame_index - prior.frame_index
        if age <= 0 or age > self.params.prior_max_age_frames:
            return None
        return prior

    def _invalid(
        self, frame_index: int, reason: str, excluded: dict[str, str] | None = None
    ) -> PoseEstimate:
        return PoseEstimate(
            frame_index=frame_index,
            valid=False,
            rotation=np.full((3, 3), np.nan),
            position=np.full(3, np.nan),
            reprojection_errors={i: math.nan for i in self.scene.landmark_ids},
            used_landmarks=(),
            reason=reason,
            excluded_landmarks=dict(excluded or {}),
        )


# ---------------------------------------------------------------------------------------------
# The tracking + localisation pipeline


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


def localize_sequence(
    frames: Iterable[np.ndarray],
    scene: Scene,
    init_boxes: Mapping[str, Box] | Sequence[Box],
    tracker_params: TrackerParams,
    localizer_params: LocalizerParams | None = None,
    assignment_known: bool = True,
    threads: int = 1,
    refine_params: RefineParams | None = None,
    reacquire_params: ReacquireParams | None = None,
) -> Iterator[LocalizationFrame]:
    """Track every landmark and estimate the camera pose frame by frame.

    `init_boxes` gives the first frame's boxes (x, y, w, h, 0-based pixels): landmark id -> box
    when `assignment_known`, otherwise a list (or a mapping with arbitrary keys) of boxes whose
    landmarks the correspondence search finds on the first frame. `refine_params` turns on the
    sub-pixel refinement of the landmark points (autotrack.refine), `reacquire_params` the
    out-of-view gating and re-acquisition of lost landmarks (autotrack.reacquire; it uses the
    refiner's templates, so it turns refinement on with default settings if needed).
    """
    if assignment_known:
        if not isinstance(init_boxes, Mapping):
            raise InputError("with a known assignment, the boxes must map landmark id -> box")
        boxes = {str(k): tuple(float(v) for v in b) for k, b in init_boxes.items()}
        for landmark_id in boxes:
            scene.landmark(landmark_id)
    else:
        listed = list(init_boxes.values()) if isinstance(init_boxes, Mapping) else list(init_boxes)
        boxes = assign_boxes([tuple(float(v) for v in b) for b in listed], scene)
    for landmark_id, box in boxes.items():
        if len(box) != 4 or not all(math.isfinite(v) for v in box) or box[2] <= 0 or box[3] <= 0:
            raise BoxError(f"box of landmark {landmark_id} must be [x, y, w, h] with w, h > 0")
    # The tracker pulls in numba-compiled features: import it here so that the pose maths, TUM
    # files and metrics stay light to import (as the package's own __init__ does).
    from autotrack.multi import MultiTracker

    localizer = Localizer(scene, localizer_params or LocalizerParams())
    tracker = MultiTracker(tracker_params, tuple(boxes), threads=threads)
    if reacquire_params is not None and refine_params is None:
        refine_params = RefineParams()
    refiner = PointRefiner(refine_params) if refine_params is not None else None
    keeper = LandmarkKeeper(scene, reacquire_params) if reacquire_params is not None else None
    try:
        for frame_index, frame in enumerate(frames):
            if frame_index == 0:
                _check_frame_size(frame, scene.camera)
            tracks = tracker.init(frame, boxes) if frame_index == 0 else tracker.update(frame)
            centres = {i: r.center for i, r in tracks.items()}
            points, refined, events = dict(centres), {}, {}
            if refiner is not None:
                # The template centre is the given first box's centre: the tracker's own first
                # box is snapped to its grid and can be a pixel or two off.
                found = (
                    refiner.init(frame, boxes)
                    if frame_index == 0
                    else refiner.refine(frame, {i: r.box for i, r in tracks.items()})
                )
                points = {i: p.point for i, p in found.items()}
                refined = {i: p.refined for i, p in found.items()}
            if keeper is not None:
                for landmark_id, why in keeper.out_of_view(frame_index).items():
                    points[landmark_id] = (math.nan, math.nan)
                    events[landmark_id] = why
            pose = localizer.estimate(
                frame_index,
                points,
                confidences={i: r.peak_score for i, r in tracks.items()},
                aberrant={i: r.aberrant for i, r in tracks.items()},
                landmark_weights=fallback_weights(refined, refine_params),
            )
            if keeper is not None and refiner is not None:
                templates = {i: refiner.template_of(i) for i in boxes if refiner.has_template(i)}
                for found_again in keeper.observe(
                    frame_index, to_grey(frame), pose, boxes, templates
                ):
                    landmark_id = found_again.landmark_id
                    tracker.reset_target(landmark_id, frame, found_again.box)
                    refiner.restart(landmark_id)
                    localizer.forget_landmark(landmark_id)
                    u, v = (
                        found_again.box[0] + found_again.box[2] / 2,
                        found_again.box[1] + found_again.box[3] / 2,
                    )
                    events[landmark_id] = (
                        f"re-acquired at ({u:.1f}, {v:.1f}), match {found_again.match:.2f}"
                    )
            yield LocalizationFrame(frame_index, tracks, points, pose, centres, refined, events)
    finally:
        tracker.close()


def fallback_weights(
    refined: Mapping[str, bool], params: RefineParams | None
) -> dict[str, float] | None:
    """Solver weights when refinement is on: a landmark whose refined point was rejected (its
    box centre is pixels off) counts `params.fallback_weight` while three others are refined."""
    if params is None or sum(refined.values()) < 3:
        return None
    return {i: 1.0 if ok else params.fallback_weight for i, ok in refined.items()}


def _check_frame_size(frame: np.ndarray, camera: CameraIntrinsics) -> None:
    height, width = frame.shape[:2]
    if (width, height) != (camera.width, camera.height):
        raise InputError(
            f"frames are {width}x{height} but the scene's camera is calibrated for "
            f"{camera.width}x{camera.height}: use intrinsics for this image size"
        )


# ---------------------------------------------------------------------------------------------
# Trajectories: TUM files and the paper's Table 3 figures


def write_tum(
    path: str | Path,
    timestamps: Sequence[float] | np.ndarray,
    positions: np.ndarray,
    quaternions_xyzw: np.ndarray,
) -> int:
    """Write a TUM trajectory (`timestamp tx ty tz qx qy qz qw`, camera-to-world, metres).

    Rows with a non-finite value (invalid poses) are skipped; returns the number written.
    """
    timestamps = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    quaternions = np.asarray(quaternions_xyzw, dtype=np.float64).reshape(-1, 4)
    if not len(timestamps) == len(positions) == len(quaternions):
        raise InputError("timestamps, positions and quaternions must have the same length")
    lines = ["# timestamp tx ty tz qx qy qz qw (camera-to-world, metres)"]
    written = 0
    for stamp, position, quaternion in zip(timestamps, positions, quaternions, strict=True):
        row = np.concatenate([[stamp], position, quaternion])
        if not np.all(np.isfinite(row)):
            continue
        lines.append(" ".join(f"{v:.6f}" if k == 0 else f"{v:.9g}" for k, v in enumerate(row)))
        written += 1
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return written


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a TUM trajectory: timestamps (n,), positions (n, 3), quaternions xyzw (n, 4)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise InputError(f"cannot read trajectory {path}: {error.strerror or error}") from None
    rows = []
    for line_number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = stripped.replace(",", " ").split()
        try:
            values = [float(v) for v in fields]
        except ValueError:
            values = []
        if len(values) != 8:
            raise InputError(
                f"{path}, line {line_number}: expected 8 numbers 'timestamp tx ty tz qx qy qz qw'"
            )
        rows.append(values)
    table = np.array(rows, dtype=np.float64).reshape(-1, 8)
    return table[:, 0], table[:, 1:4], table[:, 4:8]


@dataclass(frozen=True)
class TrajectoryErrors:
    """Position errors of an estimated trajectory against ground truth (paper Table 3)."""

    mean_abs_cm: tuple[float, float, float]
    """Mean |error| along world x, y, z (cm) over the frames with a pose."""
    rmse_cm: float
    """Root-mean-square 3-D position error (cm): sqrt(mean(|p - p_gt|^2))."""
    paper_rmse_cm: float
    """The figure the paper's Table 3 calls RMSE: the norm of the mean-|error| vector
    sqrt(x^2 + y^2 + z^2) (every row of the table satisfies this); never above rmse_cm."""
    max_error_cm: float
    """Largest 3-D position error (cm)."""
    frames: int
    """Ground-truth frames with an estimated pose."""
    missing_frames: int
    """Ground-truth frames with no (valid) estimate at the same timestamp."""
    errors_cm: np.ndarray = field(repr=False, compare=False)
    """Per associated frame 3-D error (cm)."""


def associate(
    timestamps_a: np.ndarray, timestamps_b: np.ndarray, max_difference_s: float = 0.01
) -> tuple[np.ndarray, np.ndarray]:
    """Indices (ia, ib) pairing each stamp of `b` with the nearest stamp of `a` within tolerance."""
    a = np.asarray(timestamps_a, dtype=np.float64)
    b = np.asarray(timestamps_b, dtype=np.float64)
    if len(a) == 0 or len(b) == 0:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    order = np.argsort(a)
    sorted_a = a[order]
    right = np.clip(np.searchsorted(sorted_a, b), 0, len(a) - 1)
    left = np.clip(right - 1, 0, len(a) - 1)
    nearest = np.where(np.abs(sorted_a[left] - b) <= np.abs(sorted_a[right] - b), left, right)
    matched = np.abs(sorted_a[nearest] - b) <= max_difference_s
    return order[nearest[matched]], np.flatnonzero(matched)


def trajectory_errors(
    timestamps: np.ndarray,
    positions: np.ndarray,
    gt_timestamps: np.ndarray,
    gt_positions: np.ndarray,
    max_difference_s: float = 0.01,
) -> TrajectoryErrors:
    """Table-3 errors of `positions` (metres) against ground truth, matched by timestamp.

    Positions with NaN (invalid frames) count as missing.
    """
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    gt_positions = np.asarray(gt_positions, dtype=np.float64).reshape(-1, 3)
    finite = np.all(np.isfinite(positions), axis=1)
    index_est, index_gt = associate(np.asarray(timestamps)[finite], gt_timestamps, max_difference_s)
    difference = (positions[finite][index_est] - gt_positions[index_gt]) * 100.0
    frames = len(index_gt)
    if frames == 0:
        nan = math.nan
        return TrajectoryErrors((nan, nan, nan), nan, nan, nan, 0, len(gt_timestamps), np.zeros(0))
    mean_abs = np.mean(np.abs(difference), axis=0)
    errors = np.linalg.norm(difference, axis=1)
    return TrajectoryErrors(
        mean_abs_cm=(float(mean_abs[0]), float(mean_abs[1]), float(mean_abs[2])),
        rmse_cm=float(np.sqrt(np.mean(errors**2))),
        paper_rmse_cm=float(np.linalg.norm(mean_abs)),
        max_error_cm=float(errors.max()),
        frames=frames,
        missing_frames=len(gt_timestamps) - frames,
        errors_cm=errors,
    )


def format_table3(rows: Sequence[tuple[str, TrajectoryErrors]]) -> str:
    """The paper's Table 3 layout (x, y, z mean |error|, RMSE in cm, frames) plus our columns.

    Adds the paper's RMSE form, the largest error and the frames without a trusted pose; the
    'Average' row averages the rows as the paper does, 'All frames' pools every frame.
    """
    header = (
        f"{'Dataset':<20}{'x(cm)':>8}{'y(cm)':>8}{'z(cm)':>8}{'RMSE':>8}"
        f"{'paperRMSE':>11}{'max(cm)':>9}{'Frames':>8}{'invalid':>9}"
    )
    lines = [header, "-" * len(header)]

    def line(
        name: str,
        x: float,
        y: float,
        z: float,
        rmse: float,
        paper: float,
        worst: float,
        frames: float,
        missing: float,
    ) -> str:
        return (
            f"{name:<20}{x:>8.2f}{y:>8.2f}{z:>8.2f}{rmse:>8.2f}{paper:>11.2f}{worst:>9.2f}"
            f"{frames:>8.0f}{missing:>9.0f}"
        )

    for name, e in rows:
        lines.append(
            line(
                name,
                *e.mean_abs_cm,
                e.rmse_cm,
                e.paper_rmse_cm,
                e.max_error_cm,
                e.frames,
                e.missing_frames,
            )
        )
    if len(rows) > 1:
        stats = [e for _, e in rows]
        means = np.array([e.mean_abs_cm for e in stats]).mean(axis=0)
        lines.append("-" * len(header))
        lines.append(
            line(
                "Average",
                *means,
                float(np.mean([e.rmse_cm for e in stats])),
                float(np.linalg.norm(means)),
                max(e.max_error_cm for e in stats),
                float(np.mean([e.frames for e in stats])),
                float(np.mean([e.missing_frames for e in stats])),
            )
        )
        pooled = np.concatenate([e.errors_cm for e in stats])
        total_frames = sum(e.frames for e in stats)
        weighted = sum(np.array(e.mean_abs_cm) * e.frames for e in stats) / max(total_frames, 1)
        lines.append(
            line(
                "All frames",
                *weighted,
                float(np.sqrt(np.mean(pooled**2))),
                float(np.linalg.norm(weighted)),
                float(pooled.max()),
                total_frames,
                sum(e.missing_frames for e in stats),
            )
        )
    return "\n".join(lines)
