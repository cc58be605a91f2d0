"""autotrack+: `AutoTrack` with the changes beyond the authors' release (docs/tracker.md,
"Beyond the release"): a calibrated confidence gate with re-detection, the long-term memory
against look-alikes, the motion prior and velocity prediction, the aspect filter, rotation,
the robust variation and the acting ASR. `AutoTrack(params)` builds this class when
`params.beyond_release`; the faithful `AutoTrack.update` has none of these branches.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from autotrack.result import TrackResult
from autotrack.tracker import dcf, regularization
from autotrack.tracker.inputs import as_image
from autotrack.tracker.plus import memory, motion, redetect, robust, rotation
from autotrack.tracker.plus.aspect import AspectFilter
from autotrack.tracker.tracker import AutoTrack


class AutoTrackPlus(AutoTrack, beyond_release=True):
    """AutoTrack with the autotrack+ switches of its parameters (`TrackerParams.beyond_release`)."""

    angle = 0.0  # the target's turn (rotation.py), degrees
    aspect_filter: AspectFilter | None = None

    def init(self, frame: np.ndarray, box: Sequence[float]) -> TrackResult:
        """`AutoTrack.init`, then the state of the enabled extensions."""
        result = super().init(frame, box)
        p = self.params
        image = self._prepare(as_image(frame))
        # rotation.py's state: the angle, the highest peak since the angle was last checked
        self.angle, self.aligned_peak, self.turning = 0.0, math.inf, False
        self.memory = memory.LongTermMemory(self.filter_f, p.memory_rate) if p.memory_rate else None
        self.peak_separation = max(2.0, min(self.region_size) / 2.0)  # another object, in cells
        self.aspect_filter = self._start_aspect_filter(image)
        self.confidence = (
            robust.ResponseConfidence(p.confidence_memory) if p.confidence_gate > 0 else None
        )
        self.velocity = np.zeros(2)
        self.unconfident_frames = 0  # consecutive frames below the confidence gate
        self.lookalike_seen = False  # a look-alike within the box on the last confident frame
        self.motion = motion.MotionModel(p.confidence_memory) if p.motion_prior else None
        return result

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
        # The memory's check found a single distinct peak: no look-alike for the scale guard.
        single_peak = self.memory is not None and not ambiguous
        if chosen is not None:
            disp_row, disp_col, peak_score = chosen
        confident = self._is_confident(peak_score, response)
        self.unconfident_frames = 0 if confident else self.unconfident_frames + 1
        if self.unconfident_frames >= p.redetect_patience and p.redetect_span:
            found = self._redetect(image, peak_score)
            if found is not None:
                zf, response, (disp_row, disp_col, peak_score), search_box = found
                single_peak = False  # another response, not checked
                confident = True
                self.unconfident_frames = 0
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
            best_scale, scale = self.scale_filter.detect(*upright, self.scale)
            displacement = (disp_row, disp_col)
            lookalike = not single_peak and self._absorbs_lookalike(
                response, displacement, max(scale, self.scale)
            )
            if scale > self.scale and lookalike and self.lookalike_seen:
                best_scale, scale = (p.num_scales + 1) // 2 - 1, self.scale  # the scale held
            self.lookalike_seen = lookalike
            self.scale = scale
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

        return self._result(
            search_box, peak_score, response, variation, eta, theta_ref, theta, aberrant
        )

    # -- helpers ----------------------------------------------------------------------------

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

    def _disambiguate(
        self, response: np.ndarray, zf: np.ndarray
    ) -> tuple[tuple[float, float, float] | None, bool]:
        """With a look-alike in the search region, the peak the long-term memory supports
        (memory.disambiguate): (that peak or None, whether a distractor is present)."""
        if self.memory is None:
            return None, False

        def memory_response() -> np.ndarray:  # only with a second peak
            return self.memory.response(zf, self.grid_size)

        ratio, separation = self.params.distractor_ratio, self.peak_separation
        prior = None
        if self.motion is not None:
            floor = self.params.motion_prior * min(self._box_size_hw())
            prior = self.motion.prior(floor, self.params.cell_size * self.scale)
        margin = self.params.memory_margin
        return memory.disambiguate(response, memory_response, ratio, separation, prior, margin)

    def _absorbs_lookalike(
        self, response: np.ndarray, displacement: tuple[float, float], grown_scale: float
    ) -> bool:
        """Whether the box grown to `grown_scale` would take in a look-alike: a distinct peak of
        this frame's response (memory.distinct_peaks) within `lookalike_reach` box sizes of the
        target's, on both axes (memory.lookalike_within); never without `lookalike_reach`."""
        p = self.params
        if not p.lookalike_reach:
            return False
        grown_hw = self._box_size_hw() * (grown_scale / self.scale)  # the aspect filter's shape
        cell_px = p.cell_size * self.scale
        peaks = memory.distinct_peaks(response, p.distractor_ratio, self.peak_separation)
        return memory.lookalike_within(
            peaks, displacement, response.shape, p.lookalike_reach * grown_hw / cell_px
        )

    def _is_confident(
        self, peak_score: float, response: np.ndarray, gate: float | None = None
    ) -> bool:
        """Whether this detection clears the confidence gate, or `gate` if given (always True
        without a gate)."""
        if self.confidence is None:
            return True
        confidence = self.confidence.confidence(peak_score, robust.apce(response))
        return confidence >= (self.params.confidence_gate if gate is None else gate)

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
        `rotation_step`, when that peak fell by `rotation_margin` below the highest since the
        angle was last checked (a turn lowers the match; a turned sample wins only by that
        margin over the current one, and at best it restores the match the target had at its
        angle, so a smaller drop cannot be a turn it would take) or the target turned on the
        last frame, one step either way is tried and taken if it wins
        (`rotation.turn_wins`: a peak higher by `rotation_margin`, a response as sharp) and
        still matches the filter: a confidence of at least the gate squared (0.49, the gate's
        APCE level). A turning target keeps about half its usual peak (MotorRolling's flips:
        0.52 and up); a lost tracker's samples of the background score 0.1-0.2 upright or
        turned, and a turn taken then only spins the filter away from where re-detection would
        find the target. No turn on a target too small to show one (`_turns_resolved`)."""
        p = self.params
        sampler = self._sampler(image)
        best = self._detect_patch(sampler.patch(self.angle))
        peak = best[2][2]
        held = peak * (1.0 + p.rotation_margin) >= self.aligned_peak
        if not self._turns_resolved() or (held and not self.turning):
            self.aligned_peak = max(self.aligned_peak, peak)
            return best
        best_angle = self.angle
        for angle in rotation.candidate_angles(self.angle, p.rotation_step)[1:]:
            turned = self._detect_patch(sampler.patch(angle))
            if rotation.turn_wins(turned[1:], best[1:], p.rotation_margin) and (
                self._is_confident(turned[2][2], turned[1], p.confidence_gate**2)
            ):
                best, best_angle = turned, angle
        self.turning = best_angle != self.angle
        self.angle = rotation.wrapped(best_angle)
        self.aligned_peak = best[2][2]
        return best

    def _turns_resolved(self) -> bool:
        """Whether one `rotation_step` moves the ends of the target's long side by half a
        feature cell or more, in image pixels: a cell is `cell_size` x the scale factor, and
        never less than `cell_size` (a small target's patch is upsampled, which adds cells,
        not detail). On a smaller target (a car of 11 x 8 px: 0.95 px at 10 degrees against
        2 px) a turn is not seen, only noise is, and each spurious turn reshapes the reported
        box (rotation.bounding_size)."""
        p = self.params
        if not p.rotation_step:
            return False
        half_long_side = float(np.max(self._box_size_hw())) / 2.0
        half_cell = p.cell_size * max(self.scale, 1.0) / 2.0
        return half_long_side * math.sin(math.radians(p.rotation_step)) >= half_cell

    def _upright(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(image, position) for the scale filter: the frame itself, or with the target turned,
        a view around it turned upright that holds the largest scale sample of this frame's
        scale search and of the update after it (one step further), with a pixel to spare on
        each side (the samples are axis-aligned in the view: its size is theirs)."""
        if self.angle == 0.0:
            return image, self.position
        steps = self.scale_filter.scale_steps[0] ** 2
        largest_hw = self.scale_filter.base_target_size_hw * self.scale * steps
        size_hw = (int(math.ceil(largest_hw[0])) + 2, int(math.ceil(largest_hw[1])) + 2)
        return rotation.upright_view(image, self.position, self.angle, size_hw)

    def _sampler(self, image: np.ndarray) -> rotation.TurnedSampler:
        """This frame's search region at the current position and scale, at any angle."""
        rows, cols = self._search_region()
        output = (int(self.window_size[0]), int(self.window_size[1]))
        region = (int(rows), int(cols))
        return rotation.TurnedSampler(
            image, self.position, region, output, self.backend.search_patch
        )

    def _features_spectrum(self, image: np.ndarray) -> np.ndarray:
        patch = self._sampler(image).patch(self.angle)
        return self.backend.feature_spectrum(patch, self.cos_window)

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
