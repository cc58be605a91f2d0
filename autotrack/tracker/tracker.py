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
from autotrack.tracker import dcf, regularization
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

    beyond_release: type[AutoTrack] | None = None
    """The subclass `AutoTrack(params)` makes when `params.beyond_release` (autotrack+:
    `tracker.plus.tracker.AutoTrackPlus`, which names itself here when its module is loaded,
    as the `autotrack.tracker` package does): this class stays the paper's."""

    def __init_subclass__(cls, *, beyond_release: bool = False, **options) -> None:
        super().__init_subclass__(**options)
        if beyond_release:
            AutoTrack.beyond_release = cls

    def __new__(cls, params: TrackerParams | None = None, colour_table: np.ndarray | None = None):
        """`AutoTrack(params)` with any change beyond the release switched on is an
        `AutoTrack.beyond_release` instance (autotrack+)."""
        if cls is AutoTrack and params is not None and params.beyond_release:
            if AutoTrack.beyond_release is None:
                raise RuntimeError("autotrack.tracker.plus.tracker was not loaded")
            cls = AutoTrack.beyond_release
        return super().__new__(cls)

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
        self.backend = make_backend(
            p, self.colour_table, channels, self.grid_size, colour=not self.grey
        )
        self.scale_filter = ScaleFilter(
            p,
            target_size,
            self.base_target_size,
            self.window_size,
            self.image_size_hw,
            self.backend,
        )

        self.frame_number = 1
        search_box = self._search_box()
        xf = self._features_spectrum(image)
        self.filter_f = np.zeros_like(xf)
        self.filter_f, theta = self._train(xf, theta_start=0.0, theta_ref=0.0)
        self.scale_filter.update(image, self.position, self.scale, best=None)
        self.previous_response: np.ndarray | None = None
        self.previous_displacement = (0.0, 0.0)
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
        search_box = self._search_box()
        # Detection (eq. 16) and the sub-pixel peak.
        zf, response, (disp_row, disp_col, peak_score) = self._detect(image)
        # Response variations (eq. 2), theta_ref and the aberrance stop (eq. 4), ASR (eq. 3).
        variation, eta, aberrant, theta_ref = self._regularize(response, (disp_row, disp_col))
        self.previous_response = response
        self.previous_displacement = (disp_row, disp_col)
        # Translation in pixels, then the scale search at the new position.
        translation = dcf.matlab_round(np.array([disp_row, disp_col]) * p.cell_size * self.scale)
        self.position = self.position + translation
        best_scale, self.scale = self.scale_filter.detect(image, self.position, self.scale)
        # Train (eqs. 8-15) on the detection features moved to the new position (the release's
        # reuse, converted to cells with the updated scale); an aberrant frame keeps the filter.
        theta = float("nan")
        if not aberrant:
            cells = translation / (p.cell_size * self.scale)
            xf = dcf.shift_spectrum(zf, cells[0], cells[1], self.grid_size)
            theta_start = p.zeta if p.adaptive_temporal else p.fixed_theta
            self.filter_f, theta = self._train(xf, theta_start, theta_ref)
        self.scale_filter.update(image, self.position, self.scale, best_scale)
        return self._result(
            search_box, peak_score, response, variation, eta, theta_ref, theta, aberrant
        )

    def _result(
        self, search_box, peak_score, response, variation, eta, theta_ref, theta, aberrant
    ) -> TrackResult:
        """This frame's `TrackResult` (kept as `last_result`)."""
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

    def _regularize(
        self, response: np.ndarray, displacement: tuple[float, float]
    ) -> tuple[np.ndarray | None, float, bool, float]:
        """Variation maps (eq. 2), eta, the aberrance stop and theta_ref (eq. 4), ASR (eq. 3).

        Returns (local variation or None, eta, aberrant, theta_ref); updates the spatial window.
        """
        p = self.params
        variation, eta, aberrant = None, float("nan"), False
        theta_ref = p.zeta if p.adaptive_temporal else p.fixed_theta
        if self.frame_number > 2 and self.previous_response is not None:
            peaks = (displacement, self.previous_response, self.previous_displacement)
            variation = self.backend.local_variation(response, *peaks)
            eta = regularization.global_variation(variation)
            if p.adaptive_temporal:
                aberrant = regularization.is_aberrant(eta, p.phi)
                if not aberrant:
                    theta_ref = regularization.temporal_reference(eta, p.zeta, p.nu)
            if p.adaptive_spatial:
                self.spatial_window = regularization.adaptive_spatial_window(
                    self.base_window, variation, self.region, p.delta
                )
        return variation, eta, aberrant, theta_ref

    def _detect(self, image: np.ndarray):
        """(features spectrum, response, (row, col, peak)) of this frame's search patch."""
        return self._detect_patch(self._search_patch(image))

    def _search_patch(self, image: np.ndarray) -> np.ndarray:
        """This frame's search region at the current position and scale, resampled."""
        rows, cols = self._search_region()
        output = (int(self.window_size[0]), int(self.window_size[1]))
        return self.backend.search_patch(image, self.position, (int(rows), int(cols)), output)

    def _features_spectrum(self, image: np.ndarray) -> np.ndarray:
        return self.backend.feature_spectrum(self._search_patch(image), self.cos_window)

    def _box_size_hw(self) -> np.ndarray:
        """(height, width) of the target at the current scale, unrounded."""
        return self.base_target_size * self.scale

    def _target_size(self) -> np.ndarray:
        return dcf.matlab_round(self._box_size_hw())

    @property
    def asr_reference(self) -> tuple[float, float]:
        """(gamma of the first h-step, lambda): the scale of the acting ASR window."""
        return self.params.gamma_init, self.params.admm_lambda

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

    def _detect_patch(self, patch: np.ndarray):
        """(features spectrum, response, (row, col, peak)) of one search patch (eq. 16)."""
        zf = self.backend.feature_spectrum(patch, self.cos_window)
        response = self.backend.response(self.filter_f, zf)
        return zf, response, self.backend.peak(response, self.params.newton_iterations)

    def _search_region(self) -> tuple[float, float]:
        """matlab_round(window_size * scale) as (rows, cols) floats, recomputed only when the
        scale (or, after `init`, the window) changes: both `_search_box` and `_sampler` ask."""
        key = (self.scale, self.window_size[0], self.window_size[1])
        if key != self._region_key:
            rows, cols = dcf.matlab_round(self.window_size * self.scale)
            self._region, self._region_key = (float(rows), float(cols)), key
        return self._region

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
