"""Search-patch and scale-sample extraction: the release's 1-based index clamping and resizing."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from autotrack.tracker.sampling import (
    crop_replicate,
    resize_auto,
    scale_sizes,
    search_patch,
    sized_patches,
)


def scale_patches(image, position, base_target_size_hw, factors, model_size_hw):
    """The scale samples of `factors` (the scale filter's `sized_patches(scale_sizes(...))`)."""
    sizes = scale_sizes(base_target_size_hw, factors)
    return sized_patches(image, position, sizes, model_size_hw)


def clamped_crop(image: np.ndarray, position, size_hw) -> np.ndarray:
    """The release's indexing, literally: ys = floor(pos(1)) + (1:sz(1)) - floor(sz(1)/2),
    clamped to [1, size(im, 1)] (same for xs), then 0-based numpy indexing."""
    rows = math.floor(position[0]) + np.arange(1, size_hw[0] + 1) - size_hw[0] // 2
    cols = math.floor(position[1]) + np.arange(1, size_hw[1] + 1) - size_hw[1] // 2
    rows = np.clip(rows, 1, image.shape[0]) - 1
    cols = np.clip(cols, 1, image.shape[1]) - 1
    return image[rows[:, None], cols[None, :]]


def bilinear_resize(image: np.ndarray, size_hw) -> np.ndarray:
    """Bilinear resampling with pixel-centre alignment and edge clamping, in plain numpy."""

    def axis_weights(n_in: int, n_out: int):
        source = (np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5
        source = np.clip(source, 0, n_in - 1)
        low = np.floor(source).astype(int)
        high = np.minimum(low + 1, n_in - 1)
        return low, high, source - low

    r0, r1, fr = axis_weights(image.shape[0], size_hw[0])
    c0, c1, fc = axis_weights(image.shape[1], size_hw[1])
    trailing = (1,) * (image.ndim - 2)
    fr, fc = fr.reshape(-1, 1, *trailing), fc.reshape(1, -1, *trailing)
    top = image[r0][:, c0] * (1 - fc) + image[r0][:, c1] * fc
    bottom = image[r1][:, c0] * (1 - fc) + image[r1][:, c1] * fc
    return top * (1 - fr) + bottom * fr


def test_crop_replicate_by_hand():
    image = np.arange(20).reshape(4, 5)
    # floor(1.7) = 1: rows 1 + (1:3) - 1 = 1..3 -> 0-based 0..2;
    # floor(1.2) = 1: cols 1 + (1:4) - 2 = 0..3 -> clamped 1, 1, 2, 3 -> 0-based 0, 0, 1, 2.
    expected = np.array([[0, 0, 1, 2], [5, 5, 6, 7], [10, 10, 11, 12]])
    np.testing.assert_array_equal(crop_replicate(image, (1.7, 1.2), (3, 4)), expected)
    # Right border, floor(3.9) = 3: rows 3 + (1:2) - 1 = 3, 4 -> 0-based 2, 3;
    # floor(5.5) = 5: cols 5 + (1:2) - 1 = 5, 6 -> clamped 5, 5 -> 0-based 4, 4.
    np.testing.assert_array_equal(crop_replicate(image, (3.9, 5.5), (2, 2)), [[14, 14], [19, 19]])


@pytest.mark.parametrize("channels", [None, 3])
def test_crop_replicate_equals_the_release_index_clamping(channels):
    rng = np.random.default_rng(0)
    shape = (13, 17) if channels is None else (13, 17, channels)
    image = rng.integers(0, 256, size=shape, dtype=np.uint8)
    positions = [
        (7.0, 9.0),  # inside
        (6.5, 8.5),  # halves: floor, not round
        (1.2, 16.9),  # over the top and right borders
        (13.0, 1.0),  # bottom-left corner
        (-0.5, 4.0),  # centre above the image: floor(-0.5) = -1, not int() = 0
        (4.0, -1.5),  # centre left of the image: floor(-1.5) = -2
        (-20.3, -30.7),  # entirely outside: every pixel the corner's
        (40.0, 8.0),  # entirely below
    ]
    for position in positions:
        for size_hw in [(1, 1), (4, 6), (5, 7), (20, 3), (30, 40)]:
            patch = crop_replicate(image, position, size_hw)
            assert patch.shape[:2] == size_hw and patch.dtype == image.dtype
            np.testing.assert_array_equal(
                patch, clamped_crop(image, position, size_hw), err_msg=f"{position} {size_hw}"
            )


def test_crop_replicate_makes_at_least_one_pixel():
    image = np.arange(12.0).reshape(3, 4)
    assert crop_replicate(image, (2.0, 2.0), (0, 3)).shape == (1, 3)


def test_resize_auto_keeps_an_equal_size_patch_untouched():
    patch = np.zeros((6, 9, 3), dtype=np.uint8)
    assert resize_auto(patch, (6, 9)) is patch


def test_resize_auto_averages_areas_when_shrinking():
    rng = np.random.default_rng(1)
    patch = rng.uniform(0, 255, size=(9, 12, 3)).astype(np.float32)
    # By 3: each output pixel is the mean of its 3 x 3 block (bilinear would take the centre).
    blocks = patch.reshape(3, 3, 4, 3, 3).mean(axis=(1, 3))
    np.testing.assert_allclose(resize_auto(patch, (3, 4)), blocks, rtol=1e-5)


def test_resize_auto_is_bilinear_when_enlarging():
    rng = np.random.default_rng(2)
    patch = rng.uniform(0, 255, size=(5, 7)).astype(np.float32)
    enlarged = resize_auto(patch, (9, 11))
    assert enlarged.shape == (9, 11)
    np.testing.assert_allclose(enlarged, bilinear_resize(patch, (9, 11)), atol=1e-3)


def test_resize_auto_decides_on_the_total_area():
    rng = np.random.default_rng(3)
    patch = rng.uniform(0, 255, size=(6, 20)).astype(np.float32)
    # 10 x 8 = 80 px < 120 px: area averaging even though the rows are enlarged.
    area = cv2.resize(patch, (8, 10), interpolation=cv2.INTER_AREA)
    np.testing.assert_array_equal(resize_auto(patch, (10, 8)), area)
    # 10 x 13 = 130 px > 120 px: bilinear although the columns shrink.
    np.testing.assert_allclose(
        resize_auto(patch, (10, 13)), bilinear_resize(patch, (10, 13)), atol=1e-3
    )


def test_search_patch_is_the_clamped_crop_resampled():
    rng = np.random.default_rng(4)
    image = rng.uniform(0, 255, size=(40, 50, 3)).astype(np.float32)
    # A 12 x 12 region half outside the top-left corner, shrunk by 3 to 4 x 4.
    patch = search_patch(image, (3.6, 2.2), (12, 12), (4, 4))
    crop = clamped_crop(image, (3.6, 2.2), (12, 12))
    np.testing.assert_allclose(patch, crop.reshape(4, 3, 4, 3, 3).mean(axis=(1, 3)), rtol=1e-5)
    # Enlarged 5 x 5 -> 10 x 10 around an inside position.
    patch = search_patch(image, (20.0, 25.0), (5, 5), (10, 10))
    crop = clamped_crop(image, (20.0, 25.0), (5, 5))
    np.testing.assert_allclose(patch, bilinear_resize(crop, (10, 10)), atol=1e-3)


def test_scale_patches_crop_floor_of_base_size_times_factor():
    rng = np.random.default_rng(5)
    image = rng.integers(0, 256, size=(60, 80, 3), dtype=np.uint8)
    factors = np.array([1.03**2, 1.0, 1.03**-2, 0.05])
    samples = scale_patches(image, (30.0, 40.0), np.array([20.5, 31.0]), factors, (8, 6))
    assert samples.shape == (4, 8, 6, 3) and samples.dtype == np.uint8
    # floor(20.5 * 1.0609) = floor(21.75) = 21 (rounding would give 22), floor(31 * 1.0609) = 32;
    # 0.05 gives 1 x 1 pixels, raised to the release's minimum of 2. Each sample is that crop
    # resized to the model size, bit for bit (a crop one pixel larger gives other samples).
    for sample, crop_size in zip(samples, [(21, 32), (20, 31), (19, 29), (2, 2)], strict=True):
        crop = crop_replicate(image, (30.0, 40.0), crop_size)
        np.testing.assert_array_equal(sample, resize_auto(crop, (8, 6)))


def test_scale_patch_at_the_model_size_is_the_plain_crop():
    rng = np.random.default_rng(6)
    image = rng.integers(0, 256, size=(30, 40), dtype=np.uint8)
    samples = scale_patches(image, (2.5, 38.0), np.array([8.0, 6.0]), np.array([1.0, 2.0]), (8, 6))
    np.testing.assert_array_equal(samples[0], clamped_crop(image, (2.5, 38.0), (8, 6)))
    # Twice the size, 16 x 12 -> 8 x 6: 2 x 2 block means of the clamped crop.
    big = clamped_crop(image, (2.5, 38.0), (16, 12)).astype(np.float64)
    np.testing.assert_allclose(samples[1], big.reshape(8, 2, 6, 2).mean(axis=(1, 3)), atol=0.51)
