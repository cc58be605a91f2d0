"""The fast backend: the reference steps in numba kernels, buffers kept between frames."""

from __future__ import annotations

import numpy as np

from autotrack.params import TrackerParams
from autotrack.tracker.backend import (
    fast_dcf,
    fast_features,
    fast_regularization,
    fast_sampling,
)
from autotrack.tracker.dcf import admm_settings


class FastBackend:
    """`backend.Backend` on compiled kernels; each step is tested against `ReferenceBackend`."""

    name = "fast"

    def __init__(
        self, params: TrackerParams, colour_table, channels: int, grid_size: tuple[int, int]
    ) -> None:
        self.params, self.colour_table, self.grid_size = params, colour_table, grid_size
        self.settings = admm_settings(params)
        self.transform = fast_dcf.SpectrumTransform(channels, grid_size)

    search_patch = staticmethod(fast_sampling.search_patch)
    sized_patches = staticmethod(fast_sampling.sized_patches)
    scale_features = staticmethod(fast_features.scale_features)
    peak = staticmethod(fast_dcf.newton_peak)
    local_variation = staticmethod(fast_regularization.local_variation)

    def feature_maps(self, patch: np.ndarray) -> np.ndarray:
        return fast_features.feature_maps(patch, self.params, self.colour_table)

    def feature_spectrum(self, patch: np.ndarray, window: np.ndarray) -> np.ndarray:
        maps = self.transform.input_maps
        fast_features.feature_maps(patch, self.params, self.colour_table, window, out=maps)
        return self.transform.forward(maps)

    def train(self, xf, yf, g_prev, spatial_window, theta, theta_rule=None):
        return fast_dcf.train_filter(
            xf, yf, g_prev, spatial_window, theta, self.settings, self.transform, theta_rule
        )

    def response(self, g_f: np.ndarray, zf: np.ndarray) -> np.ndarray:
        return fast_dcf.detection_response(g_f, zf, self.grid_size)
