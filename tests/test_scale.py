"""The DSST-style scale filter: its grids and guards as in the release, its per-step maths, and
scale recovery on a synthetic target of known size."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from autotrack.params import TrackerParams
from autotrack.tracker.backend import ReferenceBackend
from autotrack.tracker.scale import ScaleFilter, symmetric_hann

PARAMS = TrackerParams()
STEP = PARAMS.scale_step
IMAGE_HW = (240, 320)
CENTRE = (120.0, 160.0)  # 0-based pixel centre of the synthetic target
POSITION = (121.0, 161.0)  # the same centre in the release's 1-based coordinates
SIDE = 48.0


def make_filter(
    params: TrackerParams = PARAMS,
    target_hw=(SIDE, SIDE),
    search_hw=(108.0, 108.0),
    image_hw=IMAGE_HW,
) -> ScaleFilter:
    target = np.asarray(target_hw, dtype=np.float64)
    search = np.asarray(search_hw, dtype=np.float64)
    return ScaleFilter(
        params, target, target, search, image_hw, ReferenceBackend(params, None, (1, 1))
    )


def _texture(rng: np.random.Generator, size: int = 64) -> np.ndarray:
    texture = np.zeros((size, size, 3), dtype=np.float32)
    texture[:] = (200, 40, 40)
    for _ in range(14):
        centre = tuple(int(v) for v in rng.integers(0, size, size=2))
        radius = int(rng.integers(size // 10, size // 4))
        colour = tuple(float(v) for v in rng.integers(0, 255, size=3))
        cv2.circle(texture, centre, radius, colour, thickness=-1)
    return texture


def target_image(side: float, seed: int = 0) -> np.ndarray:
    """A textured square target of `side` pixels centred on CENTRE, over smooth clutter."""
    rng = np.random.default_rng(seed)
    height, width = IMAGE_HW
    noise = rng.uniform(0, 255, size=(height // 8, width // 8, 3)).astype(np.float32)
    background = cv2.resize(noise, (width, height), interpolation=cv2.INTER_CUBIC)
    texture = _texture(rng)
    zoom = side / texture.shape[0]
    cy, cx = CENTRE
    warp = np.array(
        [[zoom, 0, cx - side / 2 - 0.5 + zoom / 2], [0, zoom, cy - side / 2 - 0.5 + zoom / 2]]
    )
    layer = cv2.warpAffine(texture, warp, (width, height), flags=cv2.INTER_LINEAR)
    ones = np.ones(texture.shape[:2], np.float32)
    mask = cv2.warpAffine(ones, warp, (width, height), flags=cv2.INTER_LINEAR)[:, :, None]
    return np.clip(background * (1 - mask) + layer * mask, 0, 255).astype(np.uint8)


def test_scale_grid_label_and_window_for_33_scales():
    scale = make_filter()
    # scaleFactors = step .^ (ceil(33/2) - (1:33)): from step^16 down to step^-16, 1 at index 16.
    np.testing.assert_allclose(scale.scale_steps, STEP ** np.arange(16.0, -17.0, -1.0), rtol=1e-12)
    assert scale.scale_steps[16] == 1.0
    # ys = exp(-0.5 * ss.^2 / sigma^2), ss = (1:33) - 17, sigma = sqrt(33) * 0.5.
    sigma = np.sqrt(33) * 0.5
    label = np.real(np.fft.ifft(scale.label_f))
    np.testing.assert_allclose(
        label, np.exp(-0.5 * (np.arange(33) - 16) ** 2 / sigma**2), atol=1e-6
    )
    # hann(33): zero at both ends, 1 in the middle, 0.5 * (1 - cos(2 pi k / 32)).
    assert scale.window[0] == 0.0 and scale.window[-1] == 0.0 and scale.window[16] == 1.0
    assert scale.window[8] == pytest.approx(0.5)


def test_even_number_of_scales_uses_the_release_grid_and_window():
    scale = make_filter(replace(PARAMS, num_scales=4))
    # ceil(4/2) = 2: factors step^(2 - (1:4)) = step^[1, 0, -1, -2]; label peak at index 1.
    np.testing.assert_allclose(scale.scale_steps, STEP ** np.array([1.0, 0.0, -1.0, -2.0]))
    assert int(np.argmax(np.real(np.fft.ifft(scale.label_f)))) == 1
    # hann(5) = [0 .5 1 .5 0] without its first entry.
    np.testing.assert_allclose(scale.window, [0.5, 1.0, 0.5, 0.0], atol=1e-7)
    np.testing.assert_allclose(symmetric_hann(5), [0.0, 0.5, 1.0, 0.5, 0.0], atol=1e-15)
    assert symmetric_hann(1).tolist() == [1.0]


@pytest.mark.parametrize(
    ("target_hw", "model_hw"),
    [
        # 40 x 60 = 2400 px > 512: factor sqrt(512 / 2400) = 0.4619 -> floor(18.48, 27.71).
        ((40.0, 60.0), (18, 27)),
        ((16.0, 32.0), (16, 32)),  # exactly 512 px: kept
        ((10.0, 20.0), (10, 20)),  # smaller: never enlarged
        ((3.0, 2.0), (4, 4)),  # below one fHOG cell: raised to 4 x 4
    ],
)
def test_scale_model_size(target_hw, model_hw):
    assert make_filter(target_hw=target_hw).model_size_hw == model_hw


def test_scale_limits_are_whole_powers_of_the_step():
    scale = make_filter(target_hw=(40.0, 40.0), search_hw=(100.0, 50.0))
    # min: step^ceil(log(max(5 ./ [100 50])) / log(step)) = step^ceil(-77.90) = step^-77.
    assert scale.min_scale == pytest.approx(STEP**-77, rel=1e-12)
    # max: step^floor(log(min([240 320] ./ [40 40])) / log(step)) = step^floor(60.62) = step^60.
    assert scale.max_scale == pytest.approx(STEP**60, rel=1e-12)
    wide = make_filter(target_hw=(40.0, 80.0), search_hw=(100.0, 50.0))
    assert wide.max_scale == pytest.approx(STEP**46, rel=1e-12)  # log(4) / log(step) = 46.90


def test_detection_clamps_the_scale_to_its_limits():
    scale = make_filter(target_hw=(40.0, 40.0), search_hw=(100.0, 50.0))
    image = target_image(40.0)
    scale.update(image, POSITION, 1.0, best=None)
    # Whatever index wins, step^80 * step^[-16..16] is above step^60 and step^-100 * ... below
    # step^-77.
    assert scale.detect(image, POSITION, STEP**80)[1] == scale.max_scale
    assert scale.detect(image, POSITION, STEP**-100)[1] == scale.min_scale


def test_detection_response_is_the_dsst_correlation_of_the_samples():
    scale = make_filter()
    first, second = target_image(SIDE), target_image(SIDE * 1.07)
    indices = np.arange(PARAMS.num_scales)
    learnt = np.fft.fft(scale._extract(first, POSITION, 1.0, indices).astype(np.float64), axis=0)
    scale.update(first, POSITION, 1.0, best=None)
    best, new_scale = scale.detect(second, POSITION, 1.0)

    # y = ifft(sum_d conj(X_d) Y_label Z_d / (sum_d |X_d|^2 + lambda)) over the scale axis.
    tested = np.fft.fft(scale._extract(second, POSITION, 1.0, indices).astype(np.float64), axis=0)
    numerator = np.fft.fft(np.exp(-0.5 * (indices - 16) ** 2 / (np.sqrt(33) * 0.5) ** 2))
    response = np.real(
        np.fft.ifft(
            np.sum(numerator[:, None] * np.conj(learnt) * tested, axis=1)
            / (np.sum(np.abs(learnt) ** 2, axis=1) + PARAMS.scale_lambda)
        )
    )
    assert best == int(np.argmax(response))
    assert new_scale == pytest.approx(STEP ** (16 - best), rel=1e-12)


def test_model_is_a_running_average_with_the_learning_rate():
    scale = make_filter()
    indices = np.arange(PARAMS.num_scales)
    images = [target_image(SIDE), target_image(SIDE, seed=1)]
    spectra = [np.fft.fft(scale._extract(im, POSITION, 1.0, indices), axis=0) for im in images]
    for image in images:
        scale.update(image, POSITION, 1.0, best=None)
    rate = PARAMS.scale_learning_rate
    numerators = [scale.label_f[:, None] * np.conj(spectrum) for spectrum in spectra]
    denominators = [np.sum(np.abs(spectrum) ** 2, axis=1) for spectrum in spectra]
    expected_numerator = (1 - rate) * numerators[0] + rate * numerators[1]
    expected_denominator = (1 - rate) * denominators[0] + rate * denominators[1]
    half = PARAMS.num_scales // 2 + 1  # the model keeps the non-negative frequencies
    np.testing.assert_allclose(scale._numerator, expected_numerator[:half], rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(scale._denominator, expected_denominator[:half], rtol=1e-4)


def test_same_image_keeps_the_scale():
    scale = make_filter()
    image = target_image(SIDE)
    scale.update(image, POSITION, 1.0, best=None)
    assert scale.detect(image, POSITION, 1.0) == (16, 1.0)


@pytest.mark.parametrize("factor", [STEP**3, STEP**6, 1.1, 1.2, STEP**-4, 0.9, 0.85])
def test_scaled_target_gives_a_scale_estimate_near_the_factor(factor):
    scale = make_filter()
    scale.update(target_image(SIDE), POSITION, 1.0, best=None)
    scaled = target_image(SIDE * factor)
    estimate, estimates = 1.0, []
    # Frames showing the target at its new size, as the tracker runs them: detect, then learn.
    for _ in range(4):
        best, estimate = scale.detect(scaled, POSITION, estimate)
        scale.update(scaled, POSITION, estimate, best)
        estimates.append(estimate)
    # The first frame already moves the right way; within a few it is within one scale step.
    assert (estimates[0] - 1.0) * (factor - 1.0) > 0
    steps_off = abs(np.log(estimates[-1] / factor) / np.log(STEP))
    assert steps_off <= 1.0 + 1e-9, estimates


@pytest.mark.parametrize("best", [10, 20, 16])
def test_shifted_samples_are_the_release_reuse_of_the_detection_samples(best):
    scale = make_filter()
    image = target_image(SIDE * 1.05)
    scale.update(target_image(SIDE), POSITION, 1.0, best=None)
    scale.detect(image, POSITION, 1.0)
    new_scale = float(scale.scale_steps[best])
    reused = scale._shifted_samples(image, POSITION, new_scale, best)

    # Fresh samples at the new scale: index i is the old index i + shift (shift = best - 16).
    n, shift = PARAMS.num_scales, best - 16
    fresh = scale._extract(image, POSITION, new_scale, np.arange(n))
    if shift == 0:
        assert reused is scale._samples
        return
    # shift_sample_scale: out(j) = xs(j + shift) / (w(j + shift) + 1e-5) * w(j); the window's
    # zero end makes one reused sample zero; the |shift| missing ones are extracted afresh.
    source = np.arange(n) + shift
    kept = (source >= 0) & (source < n)
    factor = np.ones(n)
    factor[kept] = scale.window[source[kept]] / (scale.window[source[kept]] + 1e-5)
    np.testing.assert_allclose(reused, fresh * factor[:, None], rtol=2e-4, atol=1e-6)
    zero_end = int(np.flatnonzero(source == (0 if shift < 0 else n - 1))[0])
    assert not np.any(reused[zero_end]) and np.any(fresh[zero_end])

    # update() after a detection learns from exactly these reused samples.
    previous = scale._numerator.copy()
    scale.update(image, POSITION, new_scale, best)
    rate = PARAMS.scale_learning_rate
    learnt = scale.label_f[:, None] * np.conj(np.fft.fft(reused, axis=0))
    learnt = learnt[: n // 2 + 1]  # the model keeps the non-negative frequencies
    np.testing.assert_allclose(
        scale._numerator, (1 - rate) * previous + rate * learnt, rtol=1e-4, atol=1e-4
    )


def test_update_at_the_detected_scale_learns_this_frames_transform_exactly():
    """Without a scale change, update reuses the transform detect just computed: the model is
    the one learnt from a fresh transform of this frame's samples (to float32 rounding: the
    kernel rounds the running average's products one at a time, numpy with FMA)."""
    import scipy.fft

    scale = make_filter()
    scale.update(target_image(SIDE), POSITION, 1.0, best=None)
    rate = PARAMS.scale_learning_rate
    for seed, side in ((1, SIDE), (2, SIDE * 1.01), (3, SIDE * 0.99)):
        image = target_image(side, seed=seed)
        scale.detect(image, POSITION, 1.0)
        numerator, denominator = scale._numerator.copy(), scale._denominator.copy()
        samples_f = scipy.fft.fft(scale._samples.copy(), axis=0, workers=1)
        scale.update(image, POSITION, 1.0, best=PARAMS.num_scales // 2)
        samples_f = samples_f[: PARAMS.num_scales // 2 + 1]  # the model's frequencies
        learnt = scale.label_f[: len(samples_f), None] * np.conj(samples_f)
        energy = np.sum(np.real(samples_f * np.conj(samples_f)), axis=1)
        expected = (1 - rate) * numerator + rate * learnt
        np.testing.assert_allclose(
            scale._numerator, expected, rtol=0, atol=1e-6 * abs(expected).max()
        )
        expected = (1 - rate) * denominator + rate * energy
        np.testing.assert_allclose(scale._denominator, expected, rtol=1e-6)
