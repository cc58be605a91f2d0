"""DSST-style 1-D scale filter over a pyramid of fHOG scale samples (as in the release)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from autotrack.params import TrackerParams
from autotrack.tracker import pocketfft
from autotrack.tracker.features import scale_features
from autotrack.tracker.sampling import scale_patches


def symmetric_hann(n: int) -> np.ndarray:
    """MATLAB hann(n): symmetric, zero at both ends."""
    if n == 1:
        return np.ones(1)
    k = np.arange(n)
    return 0.5 * (1.0 - np.cos(2.0 * np.pi * k / (n - 1)))


def half_spectrum(samples: np.ndarray) -> np.ndarray:
    """FFT along the scale axis of real (scales, dims) samples, non-negative frequencies only:
    (scales // 2 + 1, dims) complex64, equal in value to the first rows of the full FFT
    (pocketfft computes a real input's full FFT by this real transform)."""
    return pocketfft.rfft(samples, axis=0)


@njit(cache=True, nogil=True, fastmath=False)
def _learn(numerator, denominator, label_f, samples_f, rate, first):
    """The model's running average in one pass: numerator <- (1 - rate) numerator + rate
    label conj(S), denominator <- (1 - rate) denominator + rate sum_d |S_d|^2 (or the new
    terms alone on the first frame), per scale."""
    scales, dims = samples_f.shape
    keep = np.float32(1.0 - rate)
    rate = np.float32(rate)
    for i in range(scales):
        y = label_f[i]
        energy = np.float32(0.0)
        for j in range(dims):
            sample = samples_f[i, j]
            new_re = y.real * sample.real + y.imag * sample.imag  # label conj(S)
            new_im = y.imag * sample.real - y.real * sample.imag
            energy += sample.real * sample.real + sample.imag * sample.imag
            if first:
                numerator[i, j] = complex(new_re, new_im)
            else:
                old = numerator[i, j]
                numerator[i, j] = complex(
                    keep * old.real + rate * new_re, keep * old.imag + rate * new_im
                )
        denominator[i] = energy if first else keep * denominator[i] + rate * energy


@njit(cache=True, nogil=True, fastmath=False)
def _response_spectrum(numerator, denominator, samples_f, regulariser, out):
    """out = sum_d numerator_d S_d / (denominator + lambda), per scale."""
    scales, dims = samples_f.shape
    for i in range(scales):
        acc_re = np.float32(0.0)
        acc_im = np.float32(0.0)
        for j in range(dims):
            a, b = numerator[i, j], samples_f[i, j]
            acc_re += a.real * b.real - a.imag * b.imag
            acc_im += a.real * b.imag + a.imag * b.real
        scale = np.float32(1.0) / (denominator[i] + np.float32(regulariser))
        out[i] = complex(acc_re * scale, acc_im * scale)


class ScaleFilter:
    """Scale estimation: a correlation filter along the scale axis, learnt by running average."""

    def __init__(
        self,
        params: TrackerParams,
        initial_target_size_hw: np.ndarray,
        base_target_size_hw: np.ndarray,
        search_size_hw: np.ndarray,
        image_size_hw: tuple[int, int],
    ) -> None:
        n = params.num_scales
        self.params = params
        self.base_target_size_hw = np.asarray(base_target_size_hw, dtype=np.float64)
        centre = math.ceil(n / 2)
        self.scale_steps = params.scale_step ** (centre - np.arange(1, n + 1))
        offsets = np.arange(1, n + 1) - centre
        sigma = math.sqrt(n) * params.scale_sigma_factor
        self.label_f = pocketfft.fft(np.exp(-0.5 * offsets**2 / sigma**2)).astype(np.complex64)
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
        patches = scale_patches(
            image, position, self.base_target_size_hw, scale * steps, self.model_size_hw
        )
        return scale_features(patches, self.window if every else self.window[indices])

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
        _response_spectrum(
            self._numerator,
            self._denominator,
            samples_f,
            self.params.scale_lambda,
            response_f[: samples_f.shape[0]],
        )
        mirrored = n - samples_f.shape[0]
        response_f[samples_f.shape[0] :] = np.conj(response_f[mirrored:0:-1])
        return pocketfft.ifft(response_f).real

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
        first = self._numerator is None
        if first:
            self._numerator = np.empty(samples_f.shape, np.complex64)
            self._denominator = np.empty(samples_f.shape[0], np.float32)
        rate = self.params.scale_learning_rate
        label_f = self.label_f[: samples_f.shape[0]]
        _learn(self._numerator, self._denominator, label_f, samples_f, rate, first)
