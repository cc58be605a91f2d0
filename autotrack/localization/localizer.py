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

import math
import statistics
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field

import cv2
import numpy as np

from autotrack.errors import InputError
from autotrack.localization.camera import camera_pose_from_pnp, rotation_angle_deg
from autotrack.localization.pnp import (
    Fit,
    fit_pose,
    in_front,
    p3p_solutions,
    position_std,
    refine_pose,
    reprojection,
    solve_pose,
)
from autotrack.localization.scene import Scene
from autotrack.result import PoseEstimate


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


def _describe(excluded: Mapping[str, str]) -> str:
    return "; ".join(f"{landmark_id} {why}" for landmark_id, why in excluded.items())


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
        # statistics.median: np.median's value (the middle score, or the mean of the middle two
        # as (a + b) / 2) without building an array, per landmark and frame.
        return float(statistics.median(history))

    # -- solving ---------------------------------------------------------------------------

    def _solve_redundant(
        self,
        ids: tuple[str, ...],
        image_points: np.ndarray,
        weights: np.ndarray,
        prior: _Prior | None,
    ) -> tuple[Fit | None, str]:
        """Four or more points: fit all, then drop outliers one at a time while >= 4 remain;
        with exactly four inconsistent points fall back to the three nearest the prior."""
        camera = self.scene.camera
        keep = list(range(len(ids)))
        while True:
            sub_ids = tuple(ids[k] for k in keep)
            object_points = self.scene.object_points(sub_ids)
            rvec, tvec = solve_pose(camera, object_points, image_points[keep], weights[keep])
            fit = fit_pose(camera, sub_ids, object_points, image_points[keep], rvec, tvec)
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
    ) -> tuple[Fit | None, str]:
        if prior is None:
            return None, (
                f"only three landmarks ({', '.join(ids)}) and no recent pose to choose among the "
                "P3P solutions"
            )
        chosen = self._nearest_to_prior(self._p3p_fits(ids, image_points), prior)
        if chosen is None:
            return None, f"no P3P solution from {', '.join(ids)} is in front of the camera"
        return chosen, ""

    def _p3p_fits(self, ids: tuple[str, ...], image_points: np.ndarray) -> list[Fit]:
        camera = self.scene.camera
        object_points = self.scene.object_points(ids)
        fits = []
        for rvec, tvec in p3p_solutions(camera, object_points, image_points):
            if in_front(object_points, rvec, tvec, self.params.min_depth_m):
                rvec, tvec = refine_pose(camera, object_points, image_points, rvec, tvec)
                fits.append(fit_pose(camera, ids, object_points, image_points, rvec, tvec))
        return fits

    def _nearest_to_prior(self, fits: list[Fit], prior: _Prior) -> Fit | None:
        """The fit closest to the prior, distance in units of the per-frame motion bounds."""
        params = self.params
        best: tuple[float, Fit] | None = None
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

    def _consistent(self, fit: Fit) -> bool:
        return (
            fit.rms <= self.params.max_rms_error_px
            and float(fit.errors.max()) <= self.params.max_landmark_error_px
        )

    # -- checking --------------------------------------------------------------------------

    def _checked(
        self,
        frame_index: int,
        fit: Fit,
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
            projected, _ = reprojection(
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
        if not in_front(object_points, fit.rvec, fit.tvec, params.min_depth_m):
            reasons.append("a landmark would be behind the camera")
        if fit.rms > params.max_rms_error_px:
            reasons.append(f"RMS reprojection error {fit.rms:.1f} px > {params.max_rms_error_px:g}")
        if std > params.max_position_std_m:
            reasons.append(
                f"ill-conditioned geometry (position uncertainty {std * 100:.0f} cm > "
                f"{params.max_position_std_m * 100:.0f} cm)"
            )
        reasons += self._continuity_problems(frame_index, fit, rotation, position, prior)
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

    def _continuity_problems(
        self,
        frame_index: int,
        fit: Fit,
        rotation: np.ndarray,
        position: np.ndarray,
        prior: _Prior | None,
    ) -> list[str]:
        """Why a pose is implausibly far from the previous trusted one (empty: it is not)."""
        params = self.params
        if prior is None:
            if len(fit.ids) == 3:
                return ["three-landmark pose without a recent pose to check it against"]
            return []
        reasons = []
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
        return reasons

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
