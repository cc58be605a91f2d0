"""Where a tracker's per-frame maths runs, behind one small interface (`Backend`).

- `ReferenceBackend`: the plain definitions (`tracker.sampling`, `tracker.features`,
  `tracker.fhog`, `tracker.dcf`): numpy, scipy.fft and OpenCV. It is the definition of correct.
- `FastBackend` (the default): the same steps in numba kernels (`fast_sampling`,
  `fast_features`, `fast_fhog`, `fast_dcf`, `fast_regularization`), each tested against the
  reference (tests/test_backend.py); ~10x faster, never needed for a correct result.

`TrackerParams.backend` chooses; `make_backend` builds one per tracker (the fast one keeps its
training buffers between frames).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from autotrack.params import TrackerParams
from autotrack.tracker import dcf, features, regularization, sampling
from autotrack.tracker.dcf import admm_settings


class Backend(Protocol):
    """The steps of a frame that cost time: sampling, features, training, detection, the
    response variation."""

    name: str
    params: TrackerParams

    def search_patch(self, image, position, region_size_hw, output_size_hw) -> np.ndarray:
        """The search region resampled to the patch size (`sampling.search_patch`)."""

    def sized_patches(self, image, position, sizes, model_size_hw) -> np.ndarray:
        """Patches of the given sizes resized to the model size (`sampling.sized_patches`)."""

    def feature_maps(self, patch: np.ndarray) -> np.ndarray:
        """The (channels, rows, cols) feature maps of a patch (`features.feature_maps`)."""

    def feature_spectrum(self, patch: np.ndarray, window: np.ndarray) -> np.ndarray:
        """Half spectrum of the windowed feature maps (`features.feature_maps`, `dcf.to_spectrum`)."""

    def scale_features(self, patches: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Windowed flattened fHOG of the scale samples (`features.scale_features`)."""

    def train(self, xf, yf, g_prev, spatial_window, theta, theta_rule) -> tuple[np.ndarray, float]:
        """The ADMM training of eqs. 8-15 (`dcf.train_filter`)."""

    def response(self, g_f: np.ndarray, zf: np.ndarray) -> np.ndarray:
        """The detection response of eq. 16 (`dcf.detection_response`)."""

    def peak(self, response: np.ndarray, iterations: int) -> tuple[float, float, float]:
        """The sub-pixel peak (`dcf.newton_peak`)."""

    def local_variation(
        self, response, displacement, previous_response, previous_displacement
    ) -> np.ndarray:
        """The local response variation of eq. 2 (`regularization.local_variation`)."""


class ReferenceBackend:
    """The plain numpy / scipy.fft / OpenCV definitions of every step."""

    name = "reference"

    def __init__(self, params: TrackerParams, colour_table, grid_size: tuple[int, int]) -> None:
        self.params, self.colour_table, self.grid_size = params, colour_table, grid_size
        self.settings = admm_settings(params)

    search_patch = staticmethod(sampling.search_patch)
    sized_patches = staticmethod(sampling.sized_patches)
    scale_features = staticmethod(features.scale_features)
    peak = staticmethod(dcf.newton_peak)
    local_variation = staticmethod(regularization.local_variation)

    def feature_maps(self, patch: np.ndarray) -> np.ndarray:
        return features.feature_maps(patch, self.params, self.colour_table)

    def feature_spectrum(self, patch: np.ndarray, window: np.ndarray) -> np.ndarray:
        maps = features.feature_maps(patch, self.params, self.colour_table, window)
        return dcf.to_spectrum(maps)

    def train(self, xf, yf, g_prev, spatial_window, theta, theta_rule=None):
        return dcf.train_filter(xf, yf, g_prev, spatial_window, theta, self.settings, theta_rule)

    def response(self, g_f: np.ndarray, zf: np.ndarray) -> np.ndarray:
        return dcf.detection_response(g_f, zf, self.grid_size)


def make_backend(
    params: TrackerParams,
    colour_table,
    channels: int,
    grid_size: tuple[int, int],
    colour: bool = True,
) -> Backend:
    """The backend `params.backend` names, for spectra of (channels, *grid_size) of colour (or
    grey) frames. A fast one compiles its kernels on first use, helped by a second process on
    a cold cache (`compile_ahead`)."""
    if params.backend == "reference":
        return ReferenceBackend(params, colour_table, grid_size)
    # numba: only when asked for
    from autotrack.tracker.backend import compile_ahead
    from autotrack.tracker.backend.fast import FastBackend

    compile_ahead.arm(params, colour)
    return FastBackend(params, colour_table, channels, grid_size)
