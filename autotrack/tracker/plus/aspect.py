"""Aspect-ratio estimation: a DSST-style 1-D correlation filter along log(width / height).

The release's scale filter (scale.py, DSST: Danelljan et al., BMVC 2014 / TPAMI 2017) samples the
target at one aspect ratio, so a target that turns (a car at a junction, a bird opening its wings)
keeps the first frame's box shape and loses overlap. Here a second filter of the same kind
searches the other axis of the 2-D (width, height) scale space: samples whose area is the
current target's and whose width / height ratio is the current one times step^k, each resized to
the scale model's size, fHOG features, a Gaussian label along k and a running-average model, as
DSST does along log-area. Area and aspect are orthogonal directions in (log w, log h), so the
two 1-D searches together cover the 2-D scale search at the cost of two 1-D ones (the
separable search of fDSST and of the aspect-aware scale pools of SAMF-style trackers).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft

from autotrack.tracker.scale import symmetric_hann

ASPECT_LIMIT = 4.0
"""The estimated aspect ratio stays within [1 / 4, 4] times the first frame's: a car seen from
the side and from the front, a bird with closed and open wings, not a box collapsing to a line."""


def aspect_sizes(target_size_hw: np.ndarray, ratios: np.ndarray) -> np.ndarray:
    """(N, 2) integer sample sizes with the area of `target_size_hw` and its width / height
    ratio times each of `ratios` (height / sqrt(r), width * sqrt(r)), at least 2 pixels."""
    root = np.sqrt(np.asarray(ratios, dtype=np.float64))
    size = np.asarray(target_size_hw, dtype=np.float64)
    sizes = np.stack([size[0] / root, size[1] * root], axis=1)
    return np.maximum(np.floor(sizes), 2).astype(np.int64)


class AspectFilter:
    """Width / height ratio of the target relative to the first frame's, by a 1-D DCF."""

    def __init__(
        self,
        count: int,
        step: float,
        sigma_factor: float,
        regulariser: float,
        learning_rate: float,
        model_size_hw: tuple[int, int],
        backend,
    ) -> None:
        self.count = count
        self.backend = backend  # its sized_patches and scale_features (`tracker.backend`)
        centre = math.ceil(count / 2)
        self.ratios = step ** (np.arange(1, count + 1) - centre)
        offsets = np.arange(1, count + 1) - centre
        sigma = math.sqrt(count) * sigma_factor
        self.label_f = scipy.fft.fft(np.exp(-0.5 * offsets**2 / sigma**2)).astype(np.complex64)
        window = symmetric_hann(count + 1)[1:] if count % 2 == 0 else symmetric_hann(count)
        self.window = window.astype(np.float32)
        self.regulariser = regulariser
        self.learning_rate = learning_rate
        self.model_size_hw = model_size_hw
        self.aspect = 1.0
        self._numerator: np.ndarray | None = None
        self._denominator: np.ndarray | None = None

    def size_factors(self) -> np.ndarray:
        """(height, width) factors of the current aspect: area-preserving, (1, 1) at the start."""
        root = math.sqrt(self.aspect)
        return np.array([1.0 / root, root])

    def _samples_f(self, image: np.ndarray, position, target_size_hw: np.ndarray) -> np.ndarray:
        sizes = aspect_sizes(target_size_hw, self.ratios)
        patches = self.backend.sized_patches(image, position, sizes, self.model_size_hw)
        samples = self.backend.scale_features(patches, self.window)
        return scipy.fft.fft(samples, axis=0, workers=1)

    def detect(self, image: np.ndarray, position, target_size_hw: np.ndarray) -> None:
        """Move the aspect to the best of the sampled ratios around the current box
        (`target_size_hw`: the box at the current scale and aspect)."""
        if self._numerator is None:
            return
        samples_f = self._samples_f(image, position, target_size_hw)
        response = np.real(
            scipy.fft.ifft(
                np.sum(self._numerator * samples_f, axis=1) / (self._denominator + self.regulariser)
            )
        )
        best = int(np.argmax(response))
        self.aspect = float(
            np.clip(self.aspect * self.ratios[best], 1.0 / ASPECT_LIMIT, ASPECT_LIMIT)
        )

    def update(self, image: np.ndarray, position, target_size_hw: np.ndarray) -> None:
        """Learn the appearance across ratios around the box (`target_size_hw`, as in detect)."""
        samples_f = self._samples_f(image, position, target_size_hw)
        numerator = self.label_f[:, None] * np.conj(samples_f)
        denominator = np.sum(np.real(samples_f * np.conj(samples_f)), axis=1)
        if self._numerator is None:
            self._numerator, self._denominator = numerator, denominator
            return
        rate = self.learning_rate
        self._numerator = (1 - rate) * self._numerator + rate * numerator
        self._denominator = (1 - rate) * self._denominator + rate * denominator
