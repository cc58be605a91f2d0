"""The AutoTrack tracker: detection, automatic regularisation, ADMM training, scale filter.

Follows the authors' released MATLAB code (AutoTrack_optimized.m) step by step; the comments
name the paper's equations. Positions are kept in the release's 1-based (row, col) pixel
coordinates internally and converted to 0-based (x, y, w, h) boxes at the edge.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

from autotrack.errors import InputError
from autotrack.params import TrackerParams
from autotrack.result import TrackResult
from autotrack.tracker import dcf, memory, motion, redetect, regularization, robust, rotation
from autotrack.tracker.aspect import AspectFilter
from autotrack.tracker.backend import make_backend
from autotrack.tracker.features import feature_dim, is_grey, load_colour_table
from autotrack.tracker.inputs import as_image, validate_box
from autotrack.tracker.scale import ScaleFilter

__all__ = ["AutoTrack", "CvAutoTrack", "validate_box"]


class AutoTrack:
    """AutoTrack (CVPR 2020) single-target tracker.

    `init(frame, box)` then `update(frame)` per frame; both return a `TrackResult`. Frames are
    RGB (or grey) uint8 arrays; boxes are 0-based (x, y, w, h) pixels.
    """

    _region_key: tuple[float, float, float] | None = None  # _search_region's (scale, window)

    def __init__(self, params: TrackerParams | None = None, colour_table: np.ndarray | None = None):
        self.params = params or TrackerParams()
        if self.params.colour_feature == "table" and colour_table is None:
            if not self.params.colour_table_path:
                raise InputError("colour_feature='table' needs colour_table_path (a .npy or .mat)")
            colour_table = load_colour_table(self.params.colour_table_path)
        self.colour_table = colour_table
        self.frame_number = 0
        self.last_result: TrackResult | None = None

    # -- set-up -----------------------------------------------------------------------------

    def _prepare(self, image: np.ndarray) -> np.ndarray:
        if image.ndim == 3 and self.grey:
            return np.ascontiguousarray(image[:, :, 0])
        if image.ndim == 2 and not self.grey:
            return cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
        return image

    def init(self, frame: np.ndarray, box: Sequence[float]) -> TrackResult:
        """Start tracking the target in `box` (0-based x, y, w, h) of `frame`."""
        image = as_image(frame)
        height, width = image.shape[:2]
        x, y, w, h = validate_box(box, (width, height))
        p = self.params
        self.grey = is_grey(image)
        image = self._prepare(image)
        self.image_size_hw = (height, width)

        # The release's 1-based integer centre: floor([y, x] + floor([h, w] / 2)).
        size_hw = np.array([h, w], dtype=np.float64)
        self.position = np.floor(np.array([y + 1.0, x + 1.0]) + np.floor(size_hw / 2.0))
        target_size = np.floor(size_hw)
        search_area = float(np.prod(target_size * p.search_area_scale))
        if search_area > p.max_image_sample_size:
            self.scale = math.sqrt(search_area / p.max_image_sample_size)
        elif search_area < p.min_image_sample_size:
            self.scale = math.sqrt(search_area / p.min_image_sample_size)
        else:
            self.scale = 1.0
        self.initial_scale = self.scale
        self.base_target_size = target_size / self.scale
        cell = p.cell_size
        window_side = math.sqrt(float(np.prod(self.base_target_size * p.search_area_scale)))
        self.window_size = np.full(2, float(dcf.matlab_round(window_side / cell) * cell))
        self.grid_size = (int(self.window_size[0] // cell), int(self.window_size[1] // cell))
        region_size = np.floor(self.base_target_size / cell).astype(int)
        self.region_size = (max(int(region_size[0]), 1), max(int(region_size[1]), 1))

        sigma = (
            math.sqrt(float(np.prod(np.floor(self.base_target_size / cell))))
            * p.output_sigma_factor
        )
        self.label_f = dcf.to_spectrum(dcf.gaussian_label(self.grid_size, sigma).astype(np.float32))
        self.cos_window = dcf.cosine_window(self.grid_size)
        self.base_window = regularization.base_spatial_window(
            self.grid_size, self.region_size, p.reg_window_max, p.reg_window_min
        )
        self.region = regularization.target_region(self.grid_size, self.region_size)
        self.spatial_window = self.base_window
        channels = feature_dim(p, colour=not self.grey)
        self.backend = make_backend(p, self.colour_table, channels, self.grid_size)
        self.scale_filter = ScaleFilter(
            p,
            target_size,
            self.base_target_size,
            self.window_size,
            self.image_size_hw,
            self.backend,
        )

        self.frame_number = 1
        self.angle, self.last_peak, self.turning = 0.0, math.inf, False  # rotation.py's state
        search_box = self._search_box()
        xf = self._features_spectrum(image)
        self.filter_f = np.zeros_like(xf)
        self.filter_f, theta = self._train(xf, theta_start=0.0, theta_ref=0.0)
        self.memory = memory.LongTermMemory(self.filter_f, p.memory_rate) if p.memory_rate else None
        self.peak_separation = max(2.0, min(self.region_size) / 2.0)  # another object, in cells
        self.scale_filter.update(image, self.position, self.scale, best=None)
        self.aspect_filter = self._start_aspect_filter(image)
        self.confidence = (
            robust.ResponseConfidence(p.confidence_memory) if p.confidence_gate > 0 else None
        )
        self.previous_response: np.ndarray | None = None
        self.previous_displacement = (0.0, 0.0)
        self.velocity = np.zeros(2)
        self.motion = motion.MotionModel(p.confidence_memory) if p.motion_prior else None
        result = TrackResult(
            frame_index=0,
            box=self._box(),
            peak_score=float("nan"),
            response_map=None,
            local_variation=None,
            global_variation=float("nan"),
            theta_ref=0.0,
            theta=theta,
            aberrant=False,
            scale_factor=self._relative_scale(),
            search_box=search_box,
            spatial_window=self.spatial_window,
        )
        self.last_result = result
        return result

    # -- per frame --------------------------------------------------------------------------

    def update(self, frame: np.ndarray) -> TrackResult:
        """Track the target into `frame`; returns the new box and the filter's signals."""
        image = self._checked_frame(frame)
        p = self.params
        self.frame_number += 1
        start = self.position
        if p.velocity_weight:
            self.position = self._predicted_position()
        search_box = self._search_box()

        # Detection (eq. 16) and the sub-pixel peak, over the angle pool with `rotation_step`.
        zf, response, (disp_row, disp_col, peak_score) = self._detect(image)
        chosen, ambiguous = self._disambiguate(response, zf)
        if chosen is not None:
            disp_row, disp_col, peak_score = chosen
        confident = self._is_confident(peak_score, response)
        if not confident and p.redetect_span:
            found = self._redetect(image, peak_score)
            if found is not None:
                zf, response, (disp_row, disp_col, peak_score), search_box = found
                confident = True
                start = None  # a jump, not a motion to extrapolate
        if self.confidence is not None:
            self.confidence.observe(peak_score, robust.apce(response), p.confidence_gate)

        # Response variations (eq. 2), theta_ref and the aberrance stop (eq. 4), ASR (eq. 3).
        variation, eta, aberrant, theta_ref = self._regularize(response, (disp_row, disp_col))
        self.previous_response = response
        self.previous_displacement = (disp_row, disp_col)

        # Translation in pixels and the scale search at the new position.
        best_scale = None
        shift = np.array([disp_row, disp_col]) * p.cell_size * self.scale
        translation = dcf.matlab_round(rotation.rotate_offset(shift, self.angle))
        self.position = self.position + translation
        moved = self.position - start if confident and start is not None else None
        self.velocity = moved if moved is not None else 0.0 * translation
        if self.motion is not None:
            self.motion.observe(moved)
        # A low-confidence frame (occluder, loss) changes neither the filter nor the scale.
        if confident:
            upright = self._upright(image)
            best_scale, self.scale = self.scale_filter.detect(*upright, self.scale)
            self._detect_aspect(image)

        # Train on the detection features moved to the new position (release's reuse).
        theta = float("nan")
        if not aberrant and confident:
            cells = rotation.rotate_offset(translation, -self.angle) / (p.cell_size * self.scale)
            xf = dcf.shift_spectrum(zf, cells[0], cells[1], self.grid_size)
            theta_start = p.zeta if p.adaptive_temporal else p.fixed_theta
            self.filter_f, theta = self._train(xf, theta_start, theta_ref)
            if self.memory is not None and not ambiguous:
                self.memory.learn(self.filter_f)
        if confident:
            if self.aspect_filter is not None:
                upright = self._upright(image)  # the view's side follows the new shape
            self.scale_filter.update(*upright, self.scale, best_scale)
            if self.aspect_filter is not None:
                self.aspect_filter.update(image, self.position, self._box_size_hw())

        result = TrackResult(
            frame_index=self.frame_number - 1,
            box=self._box(),
            peak_score=peak_score,
            response_map=dcf.centred_response(response),
            local_variation=variation,
            global_variation=eta,
            theta_ref=float(theta_ref),
            theta=theta,
            aberrant=aberrant,
            scale_factor=self._relative_scale(),
            search_box=search_box,
            spatial_window=None if aberrant else self.spatial_window,
        )
        self.last_result = result
        return result

    # -- helpers ----------------------------------------------------------------------------

    @property
    def asr_reference(self) -> tuple[float, float]:
        """(gamma of the first h-step, lambda): the scale of the acting ASR window."""
        return self.params.gamma_init, self.params.admm_lambda

    def _regularize(
        self, response: np.ndarray, displacement: tuple[float, float]
    ) -> tuple[np.ndarray | None, float, bool, float]:
        """Variation maps (eq. 2), eta, the aberrance stop and theta_ref (eq. 4), ASR (eq. 3).

        Returns (local variation or None, eta, aberrant, theta_ref); updates the spatial window.
        """
        p = self.params
        variation = None
        eta = float("nan")
        aberrant = False
        theta_ref = p.zeta if p.adaptive_temporal else p.fixed_theta
        if self.frame_number > 2 and self.previous_response is not None:
            peaks = (displacement, self.previous_response, self.previous_displacement)
            if p.robust_variation:
                variation = robust.robust_local_variation(response, *peaks, p.variation_floor)
            else:
                variation = regularization.local_variation(response, *peaks)
            eta = regularization.global_variation(variation)
            if p.adaptive_temporal:
                aberrant = regularization.is_aberrant(eta, p.phi)
                if not aberrant:
                    theta_ref = regularization.temporal_reference(eta, p.zeta, p.nu)
            if p.adaptive_spatial and p.acting_asr:
                asr = (p.delta, *self.asr_reference, p.asr_relative)
                self.spatial_window = robust.acting_spatial_window(
                    self.base_window, variation, self.region, *asr
                )
            elif p.adaptive_spatial:
                self.spatial_window = regularization.adaptive_spatial_window(
                    self.base_window, variation, self.region, p.delta
                )
        return variation, eta, aberrant, theta_ref

    def _checked_frame(self, frame: np.ndarray) -> np.ndarray:
        """A frame of the first frame's size, prepared like it; InputError otherwise."""
        if self.frame_number == 0:
            raise InputError("call init(frame, box) before update(frame)")
        image = as_image(frame)
        if image.shape[:2] != self.image_size_hw:
            raise InputError(
                f"frame size {image.shape[1]}x{image.shape[0]} differs from the first frame's "
                f"{self.image_size_hw[1]}x{self.image_size_hw[0]}"
            )
        return self._prepare(image)

    def _disambiguate(
        self, response: np.ndarray, zf: np.ndarray
    ) -> tuple[tuple[float, float, float] | None, bool]:
        """With a look-alike in the search region, the peak the long-term memory supports
        (memory.disambiguate): (that peak or None, whether a distractor is present)."""
        if self.memory is None:
            return None, False
        memory_response = self.memory.response(zf, self.grid_size)
        ratio, separation = self.params.distractor_ratio, self.peak_separation
        prior = None
        if self.motion is not None:
            floor = self.params.motion_prior * min(self._box_size_hw())
            prior = self.motion.prior(floor, self.params.cell_size * self.scale)
        return memory.disambiguate(response, memory_response, ratio, separation, prior)

    def _is_confident(self, peak_score: float, response: np.ndarray) -> bool:
        """Whether this detection clears the confidence gate (always True without a gate)."""
        if self.confidence is None:
            return True
        confidence = self.confidence.confidence(peak_score, robust.apce(response))
        return confidence >= self.params.confidence_gate

    def _redetect(self, image: np.ndarray, local_peak: float):
        """Wider search (redetect.py); moves the tracker and returns its detection, or None."""
        p = self.params
        offset, _ = redetect.wide_search_offset(
            image,
            self.position,
            self.scale,
            int(self.window_size[0]),
            p.redetect_span,
            self.filter_f,
            self.grid_size,
            self.cos_window,
            self.backend,
        )
        if np.max(np.abs(offset)) < p.cell_size * self.scale:
            return None  # the best placement is the current one
        saved = self.position
        height, width = self.image_size_hw
        candidate = self.position + dcf.matlab_round(offset)
        self.position = np.clip(candidate, 1.0, [float(height), float(width)])
        zf = self._features_spectrum(image)
        response = self.backend.response(self.filter_f, zf)
        peak = self.backend.peak(response, p.newton_iterations)
        # Move only to a confident place that beats the local peak by as much as the gate
        # discounts a usual peak: a look-alike no better than the target does not win.
        dominant = peak[2] * p.confidence_gate > local_peak
        if dominant and self._is_confident(peak[2], response):
            return zf, response, peak, self._search_box()
        self.position = saved
        return None

    def _detect(self, image: np.ndarray):
        """(features spectrum, response, (row, col, peak)) at the current angle; with
        `rotation_step`, when that peak fell below the last frame's (a turn lowers the match) or
        the target turned on the last frame, one step either way is tried and taken if it wins
        (`rotation.turn_wins`: a peak higher by `rotation_margin`, a response as sharp)."""
        p = self.params
        sampler = self._sampler(image)
        best = self._detect_patch(sampler.patch(self.angle))
        last_peak, self.last_peak = self.last_peak, best[2][2]
        if not p.rotation_step or (best[2][2] >= last_peak and not self.turning):
            return best
        best_angle = self.angle
        for angle in rotation.candidate_angles(self.angle, p.rotation_step)[1:]:
            turned = self._detect_patch(sampler.patch(angle))
            if rotation.turn_wins(turned[1:], best[1:], p.rotation_margin):
                best, best_angle = turned, angle
        self.turning = best_angle != self.angle
        self.angle = rotation.wrapped(best_angle)
        return best

    def _detect_patch(self, patch: np.ndarray):
        """(features spectrum, response, (row, col, peak)) of one search patch (eq. 16)."""
        zf = self.backend.feature_spectrum(patch, self.cos_window)
        response = self.backend.response(self.filter_f, zf)
        return zf, response, self.backend.peak(response, self.params.newton_iterations)

    def _upright(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(image, position) for the scale filter: the frame itself, or with the target turned,
        a view around it turned upright that holds the largest scale sample of this frame's
        scale search and of the update after it (one step further)."""
        if self.angle == 0.0:
            return image, self.position
        steps = self.scale_filter.scale_steps[0] ** 2
        largest = np.max(self.scale_filter.base_target_size_hw) * self.scale * steps
        side = int(math.ceil(largest * math.sqrt(2.0))) + 2
        return rotation.upright_view(image, self.position, self.angle, side)

    def _sampler(self, image: np.ndarray) -> rotation.TurnedSampler:
        """This frame's search region at the current position and scale, at any angle."""
        rows, cols = self._search_region()
        output = (int(self.window_size[0]), int(self.window_size[1]))
        region = (int(rows), int(cols))
        return rotation.TurnedSampler(
            image, self.position, region, output, self.backend.search_patch
        )

    def _search_region(self) -> tuple[float, float]:
        """matlab_round(window_size * scale) as (rows, cols) floats, recomputed only when the
        scale (or, after `init`, the window) changes: both `_search_box` and `_sampler` ask."""
        key = (self.scale, self.window_size[0], self.window_size[1])
        if key != self._region_key:
            rows, cols = dcf.matlab_round(self.window_size * self.scale)
            self._region, self._region_key = (float(rows), float(cols)), key
        return self._region

    def _features_spectrum(self, image: np.ndarray) -> np.ndarray:
        patch = self._sampler(image).patch(self.angle)
        return self.backend.feature_spectrum(patch, self.cos_window)

    def _theta_update(
        self, theta_ref: float, filter_prev: np.ndarray
    ) -> regularization.ThetaRule | None:
        """Eq. 13 inside ADMM (regularization.theta_update), in the parameters' variant; None
        keeps theta at its start value (0, zeta, or STRCF's fixed theta). Like every variant it
        is not re-estimated after the last iteration (train_filter stops there)."""
        p = self.params
        if not p.adaptive_temporal or self.frame_number <= 2:
            return None
        return regularization.theta_update(p.theta_update, theta_ref, filter_prev, self.grid_size)

    def _train(
        self, xf: np.ndarray, theta_start: float, theta_ref: float
    ) -> tuple[np.ndarray, float]:
        """Filter for this frame by ADMM (eqs. 8-15), warm-started from the previous one."""
        update = self._theta_update(theta_ref, self.filter_f)
        return self.backend.train(
            xf, self.label_f, self.filter_f, self.spatial_window, theta_start, update
        )

    def _predicted_position(self) -> np.ndarray:
        """Last position plus velocity_weight x the last confident frame's motion, in the image."""
        height, width = self.image_size_hw
        moved = self.position + dcf.matlab_round(self.params.velocity_weight * self.velocity)
        return np.clip(moved, 1.0, [float(height), float(width)])

    def _start_aspect_filter(self, image: np.ndarray) -> AspectFilter | None:
        """The aspect filter (num_aspects > 0) learnt on the first frame, on the scale filter's
        model size and its step, label width, regulariser and learning rate."""
        p = self.params
        if not p.num_aspects:
            return None
        self.aspect_filter = None  # _box_size_hw: the first frame's shape
        settings = (p.scale_step, p.scale_sigma_factor, p.scale_lambda, p.scale_learning_rate)
        model_size = self.scale_filter.model_size_hw
        aspect = AspectFilter(p.num_aspects, *settings, model_size, self.backend)
        aspect.update(image, self.position, self._box_size_hw())
        return aspect

    def _detect_aspect(self, image: np.ndarray) -> None:
        """Aspect search at the new scale (aspect.py); the scale filter then samples that shape."""
        if self.aspect_filter is None:
            return
        self.aspect_filter.detect(image, self.position, self._box_size_hw())
        shape = self.base_target_size * self.aspect_filter.size_factors()
        self.scale_filter.base_target_size_hw = shape

    def _box_size_hw(self) -> np.ndarray:
        """(height, width) of the target at the current scale and aspect, unrounded."""
        size = self.base_target_size * self.scale
        if self.aspect_filter is not None:
            size = size * self.aspect_filter.size_factors()
        return size

    def _target_size(self) -> np.ndarray:
        if self.angle:
            return dcf.matlab_round(rotation.bounding_size(self._box_size_hw(), self.angle))
        return dcf.matlab_round(self._box_size_hw())

    def _box(self) -> tuple[float, float, float, float]:
        height, width = self._target_size()
        row, col = self.position
        return (
            float(col - width / 2.0 - 1.0),
            float(row - height / 2.0 - 1.0),
            float(width),
            float(height),
        )

    def _search_box(self) -> tuple[float, float, float, float]:
        rows, cols = self._search_region()
        row, col = self.position
        top = math.floor(row) - int(rows) // 2
        left = math.floor(col) - int(cols) // 2
        return (float(left), float(top), cols, rows)

    def _relative_scale(self) -> float:
        return float(self.scale / self.initial_scale)


class CvAutoTrack:
    """AutoTrack with OpenCV's tracker call shape: BGR frames, `ok, box = update(frame)`."""

    def __init__(self, params: TrackerParams | None = None, colour_table: np.ndarray | None = None):
        self.tracker = AutoTrack(params, colour_table)

    @staticmethod
    def _to_rgb(frame: np.ndarray) -> np.ndarray:
        if frame.ndim == 3 and frame.shape[2] == 3:
            return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
        return frame

    def init(self, frame: np.ndarray, box: Sequence[float]) -> None:
        """Start tracking `box` (x, y, w, h) in a BGR frame."""
        self.tracker.init(self._to_rgb(frame), box)

    def update(self, frame: np.ndarray) -> tuple[bool, tuple[float, float, float, float]]:
        """(ok, box): ok is False on frames judged aberrant (the box is still the estimate)."""
        result = self.tracker.update(self._to_rgb(frame))
        return (not result.aberrant, result.box)
