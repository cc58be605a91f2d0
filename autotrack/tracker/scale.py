"""DSST-style 1-D scale filter over a pyramid of fHOG scale samples (as in the release)."""

from __future__ import annotations

import math

import numpy as np
import scipy.fft

from autotrack.params import TrackerParams
from autotrack.tracker.sampling import scale_sizes


def symmetric_hann(n: int) -> np.ndarray:
    """MATLAB hann(n): symmetric, zero at both ends."""
    if n == 1:
        return np.ones(1)
    k = np.arange(n)
    return 0.5 * (1.0 - np.cos(2.0 * np.pi * k / (n - 1)))


def half_spectrum(samples: np.ndarray) -> np.ndarray:
    """FFT along the scale axis of real (scales, dims) samples, non-negative frequencies only:
    (scales // 2 + 1, dims) complex64, equal in value to the first rows of the full FFT
    (scipy.fft.rfft along the scale axis)."""
    return scipy.fft.rfft(samples, axis=0, workers=1)


class ScaleFilter:
    """Scale estimation: a correlation filter along the scale axis, learnt by running average."""

    def __init__(
        self,
        params: TrackerParams,
        initial_target_size_hw: np.ndarray,
        base_target_size_hw: np.ndarray,
        search_size_hw: np.ndarray,
        image_size_hw: tuple[int, int],
        backend,
    ) -> None:
        n = params.num_scales
        self.params = params
        self.backend = backend  # its scale_patches and scale_features (`tracker.backend`)
        self.base_target_size_hw = np.asarray(base_target_size_hw, dtype=np.float64)
        centre = math.ceil(n / 2)
        self.scale_steps = params.scale_step ** (centre - np.arange(1, n + 1))
        offsets = np.arange(1, n + 1) - centre
        sigma = math.sqrt(n) * params.scale_sigma_factor
        self.label_f = scipy.fft.fft(np.exp(-0.5 * offsets**2 / sigma**2)).astype(np.complex64)
        window = symmetric_hann(n + 1)[1:] if n % 2 == 0 else symmetric_hann(n)
        self.window = window.astype(np.float32)
        target_area = float(np.prod(initial_target_size_hw))
        model_factor = 1.0
        if model_factor**2 * target_area > params.scale_model_max_area:
            model_factor = math.sqrt(params.scale_model_max_area / target_area)
        shortest = float(np.min(initial_target_size_hw))
        if params.scale_model_min_side and model_factor * shortest < params.scale_model_min_side:
            # autotrack+: keep >= 4 fHOG cells across a thin target (params.scale_model_min_side)
            model_factor = params.scale_model_min_side / shortest
        model_size = np.floor(np.asarray(initial_target_size_hw, dtype=np.float64) * model_factor)
        self.model_size_hw = (max(int(model_size[0]), 4), max(int(model_size[1]), 4))
        step = params.scale_step
        self.min_scale = step ** math.ceil(
            math.log(float(np.max(5.0 / np.asarray(search_size_hw)))) / math.log(step)
        )
        self.max_scale = step ** math.floor(
            math.log(float(np.min(np.asarray(image_size_hw) / self.base_target_size_hw)))
            / math.log(step)
        )
        self._all_indices = np.arange(n)
        self._numerator: np.ndarray | None = None
        self._denominator: np.ndarray | None = None
        self._samples: np.ndarray | None = None
        self._samples_f: np.ndarray | None = None  # the transform of `_samples`

    def _extract(
        self, image: np.ndarray, position, scale: float, indices: np.ndarray
    ) -> np.ndarray:
        every = indices is self._all_indices  # no gathered copies of the steps and window
        steps = self.scale_steps if every else self.scale_steps[indices]
        sizes = scale_sizes(self.base_target_size_hw, scale * steps)
        patches = self.backend.sized_patches(image, position, sizes, self.model_size_hw)
        return self.backend.scale_features(patches, self.window if every else self.window[indices])

    def detect(self, image: np.ndarray, position, scale: float) -> tuple[int, float]:
        """Best scale index and the new (clamped) scale factor."""
        self._samples = self._extract(image, position, scale, self._all_indices)
        self._samples_f = half_spectrum(self._samples)
        best = int(self.response(self._samples_f).argmax())
        new_scale = scale * float(self.scale_steps[best])
        # np.clip's value (a NaN stays NaN) on Python floats
        return best, float(min(max(new_scale, self.min_scale), self.max_scale))

    def response(self, samples_f: np.ndarray) -> np.ndarray:
        """The correlation response over the scales of samples whose `half_spectrum` is
        `samples_f`: ifft(sum_d A_d S_d / (B + lambda)) (DSST).

        The model is kept for the non-negative frequencies only: the samples being real, the
        others are their complex conjugates, bit for bit in the full FFT, and so are the model's
        and the response's (each is a sum of products of conjugated factors, which rounds to
        the conjugate), so the full spectrum is rebuilt by conjugation and transformed as
        before (the same values as the full computation, at half the work).
        """
        n = self.params.num_scales
        response_f = np.empty(n, np.complex64)
        regulariser = np.float32(self.params.scale_lambda)
        response_f[: samples_f.shape[0]] = np.sum(self._numerator * samples_f, axis=1) / (
            self._denominator + regulariser
        )
        mirrored = n - samples_f.shape[0]
        response_f[samples_f.shape[0] :] = np.conj(response_f[mirrored:0:-1])
        return scipy.fft.ifft(response_f, workers=1).real

    def _shifted_samples(self, image, position, scale: float, best: int) -> np.ndarray:
        """The release's reuse of the detection samples shifted by the chosen scale index."""
        n = self.params.num_scales
        shift = best - math.ceil(n / 2) + 1
        if shift == 0:
            return self._samples
        window = self.window
        unwindowed = self._samples / (window[:, None] + 1e-5)
        samples = np.empty_like(self._samples)
        if shift > 0:
            samples[: n - shift] = unwindowed[shift:] * window[: n - shift, None]
            missing = np.arange(n - shift, n)
        else:
            samples[-shift:] = unwindowed[: n + shift] * window[-shift:, None]
            missing = np.arange(0, -shift)
        samples[missing] = self._extract(image, position, scale, missing)
        return samples

    def update(self, image: np.ndarray, position, scale: float, best: int | None) -> None:
        """Learn from samples at `position`/`scale` (first frame: fresh; later: shifted reuse)."""
        if best is None or self._samples is None:
            samples = self._extract(image, position, scale, self._all_indices)
        else:
            samples = self._shifted_samples(image, position, scale, best)
        if samples is self._samples and self._samples_f is not None:
            samples_f = self._samples_f  # scale unchanged: the detection samples, transformed
        else:
            samples_f = half_spectrum(samples)
        # DSST's running average: A <- (1 - rate) A + rate y conj(S), B <- (1 - rate) B +
        # rate sum_d |S_d|^2 (the new terms alone on the first frame), per scale; the products
        # taken in place (the same roundings as the expressions written out).
        numerator = np.conj(samples_f)
        np.multiply(self.label_f[: samples_f.shape[0], None], numerator, out=numerator)
        denominator = np.sum(samples_f.real**2 + samples_f.imag**2, axis=1)
        if self._numerator is None:
            self._numerator, self._denominator = numerator, denominator
            return
        rate = np.float32(self.params.scale_learning_rate)
        keep = np.float32(1.0) - rate
        numerator *= rate
        self._numerator *= keep
        self._numerator += numerator
        self._denominator = keep * self._denominator + rate * denominator
