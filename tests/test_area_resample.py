"""The compiled INTER_AREA sampler gives OpenCV's samples exactly (the faithful preset's inputs)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from autotrack.tracker.backend.area_resample import (
    area_path_is_generic,
    area_paths_are_generic,
    area_resize_crop,
    area_resize_crops,
)
from autotrack.tracker.backend.fast_sampling import search_patch, sized_patches
from autotrack.tracker.sampling import crop_replicate, resize_auto, scale_sizes


def scale_patches(image, position, base_target_size_hw, factors, model_size_hw):
    """The scale samples of `factors` (the scale filter's `sized_patches(scale_sizes(...))`)."""
    sizes = scale_sizes(base_target_size_hw, factors)
    return sized_patches(image, position, sizes, model_size_hw)


def _opencv_sample(image, top, left, size_hw, out_hw):
    """The release's sample as the code computed it before: crop with replicated border + cv2."""
    rows, cols = size_hw
    crop = crop_replicate(image, (top + rows // 2, left + cols // 2), (rows, cols))
    return cv2.resize(
        np.ascontiguousarray(crop), (out_hw[1], out_hw[0]), interpolation=cv2.INTER_AREA
    )


def _images():
    rng = np.random.default_rng(7)
    noise = rng.integers(0, 256, (240, 320, 3), dtype=np.uint8)
    smooth = cv2.GaussianBlur(noise, (0, 0), 3)
    return {"noise": noise, "smooth": smooth, "grey": np.ascontiguousarray(smooth[:, :, 1])}


@pytest.mark.parametrize("kind", ["noise", "smooth", "grey"])
def test_area_samples_equal_opencv_bit_for_bit(kind):
    image = _images()[kind]
    rng = np.random.default_rng(11)
    checked = 0
    while checked < 300:
        size = tuple(int(v) for v in rng.integers(4, 200, 2))
        out = tuple(int(v) for v in rng.integers(2, 50, 2))
        if not area_path_is_generic(size, out):
            continue
        # anywhere, including crops that hang over (or lie wholly outside) the border
        top, left = int(rng.integers(-150, 300)), int(rng.integers(-150, 400))
        expected = _opencv_sample(image, top, left, size, out)
        got = area_resize_crops(image, [top], [left], np.array([size]), out)[0]
        assert got.dtype == np.uint8 and got.shape == expected.shape
        np.testing.assert_array_equal(got, expected, err_msg=f"{size} -> {out} at {top},{left}")
        checked += 1


def test_generic_path_excludes_the_cases_opencv_computes_otherwise():
    assert area_path_is_generic((100, 80), (33, 27))
    assert not area_path_is_generic((100, 80), (100, 80))  # same size: a copy
    assert not area_path_is_generic((100, 80), (50, 40))  # integer ratio: resizeAreaFast
    assert not area_path_is_generic((100, 80), (120, 40))  # enlarging rows: bilinear variant
    assert area_path_is_generic((100, 80), (50, 30))  # integer on one axis only
    sizes = np.array([(100, 80), (100, 80), (100, 80), (100, 80), (100, 80), (37, 41)])
    outs = [(33, 27), (100, 80), (50, 40), (120, 40), (50, 30), (37, 40)]
    for size, out in zip(sizes, outs, strict=True):
        assert area_paths_are_generic(size[None], out)[0] == area_path_is_generic(size, out)
    rng = np.random.default_rng(2)
    many = rng.integers(2, 120, (500, 2))
    expected = [area_path_is_generic(tuple(size), (30, 20)) for size in many]
    np.testing.assert_array_equal(area_paths_are_generic(many, (30, 20)), expected)


@pytest.mark.parametrize("kind", ["noise", "grey"])
def test_scale_patches_equal_one_opencv_resize_per_scale(kind):
    image = _images()[kind]
    factors = 1.03 ** (16 - np.arange(33))
    for base, model, position in (
        ((61.3, 47.9), (25, 19), (120.0, 160.0)),
        ((40.0, 20.0), (32, 16), (5.0, 310.0)),  # near the border: replicated pixels
        ((8.0, 6.0), (8, 6), (100.0, 100.0)),  # model = base: some scales copy or enlarge
    ):
        got = scale_patches(image, position, np.array(base), factors, model)
        for index, factor in enumerate(factors):
            size = np.maximum(np.floor(np.array(base) * factor), 2).astype(int)
            crop = crop_replicate(image, position, (size[0], size[1]))
            np.testing.assert_array_equal(got[index], resize_auto(crop, model))


@pytest.mark.parametrize("kind", ["noise", "smooth", "grey"])
def test_search_patch_equals_crop_then_opencv_resize(kind):
    image = _images()[kind]
    rng = np.random.default_rng(3)
    for _ in range(40):
        side = int(rng.integers(120, 330))
        out = int(rng.integers(100, 201)) // 4 * 4
        position = (float(rng.uniform(-20, 260)), float(rng.uniform(-20, 340)))
        crop = crop_replicate(image, position, (side, side))
        np.testing.assert_array_equal(
            search_patch(image, position, (side, side), (out, out)), resize_auto(crop, (out, out))
        )


def test_single_crop_kernel_equals_opencv_on_large_crops():
    image = _images()["smooth"]
    rng = np.random.default_rng(5)
    for _ in range(60):
        size = tuple(int(v) for v in rng.integers(50, 400, 2))
        out = tuple(int(v) for v in rng.integers(20, 250, 2))
        if not area_path_is_generic(size, out):
            continue
        top, left = int(rng.integers(-100, 200)), int(rng.integers(-100, 300))
        np.testing.assert_array_equal(
            area_resize_crop(image, top, left, size, out),
            _opencv_sample(image, top, left, size, out),
        )


def test_strided_frames_give_the_same_samples():
    """A frame that is a view into a larger array (not contiguous) samples like a copy of it."""
    base = _images()["smooth"]
    for image in (base, base[:, :, 1]):
        view = image[10:200, 20:300]
        assert not view.flags.c_contiguous
        copy = np.ascontiguousarray(view)
        for top, left in ((-30, -40), (50, 60), (150, 250)):
            np.testing.assert_array_equal(
                area_resize_crop(view, top, left, (90, 70), (40, 33)),
                area_resize_crop(copy, top, left, (90, 70), (40, 33)),
            )
            sizes = np.array([[90, 70], [61, 47]])
            np.testing.assert_array_equal(
                area_resize_crops(view, [top, top + 9], [left, left + 5], sizes, (25, 19)),
                area_resize_crops(copy, [top, top + 9], [left, left + 5], sizes, (25, 19)),
            )


def _tap_count(src: int, dst: int) -> int:
    """The most horizontal taps an output element of a src -> dst shrink takes (OpenCV's table)."""
    from autotrack.tracker.backend.area_resample import _area_taps

    first = np.empty(2 * src + 2, np.int64)
    weights = np.empty(2 * src + 2, np.float32)
    offsets = np.empty(dst + 1, np.int64)
    _area_taps(src, dst, first, weights, offsets)
    return int(np.diff(offsets).max())


@pytest.mark.parametrize("kind", ["noise", "grey"])
def test_search_patch_kernel_equals_opencv_for_every_tap_count(kind):
    """The horizontal pass special-cases 1, 2, 3 and 4 taps and then adds two at a time (an odd
    one last): every count from 1 (an unchanged width) to 8, 15 and 37 (782 -> 22) matches cv2
    exactly."""
    image = np.ascontiguousarray(np.tile(_images()[kind], (4, 3, 1)[: _images()[kind].ndim]))
    cases = [((150, 200), (101, 200))]  # the width kept: one tap an element
    cases += [((199, 201), (123, 200)), ((300, 291), (200, 200)), ((291, 446), (200, 200))]
    cases += [((230, 401), (97, 100)), ((240, 130), (100, 29)), ((130, 540), (61, 101))]
    cases += [((200, 610), (71, 101)), ((401, 782), (200, 22)), ((64, 129), (31, 9))]
    counts = set()
    for size, out in cases:
        assert area_path_is_generic(size, out)
        counts.add(_tap_count(size[1], out[1]))
        for top, left in ((37, 51), (-60, -90), (600, 700)):  # inside, over two borders
            np.testing.assert_array_equal(
                area_resize_crop(image, top, left, size, out),
                _opencv_sample(image, top, left, size, out),
                err_msg=f"{size} -> {out} at {top},{left}",
            )
    assert counts == {1, 2, 3, 4, 5, 6, 7, 8, 15, 37}


@pytest.mark.parametrize("kind", ["smooth", "grey"])
def test_crops_of_mixed_sizes_in_one_call_equal_opencv(kind):
    """The scale samples' scratch arrays are sized once for the call's largest crop and reused:
    crops in any order of size (small after large, large after small) stay exact."""
    image = _images()[kind]
    rng = np.random.default_rng(13)
    for out in ((22, 22), (27, 18), (19, 26)):
        sizes = rng.integers(out[0] + 1, 160, (40, 2))
        sizes = np.array([size for size in sizes if area_path_is_generic(tuple(size), out)])
        tops = rng.integers(-60, 200, len(sizes))
        lefts = rng.integers(-60, 280, len(sizes))
        got = area_resize_crops(image, tops, lefts, sizes, out)
        for index, size in enumerate(sizes):
            expected = _opencv_sample(image, tops[index], lefts[index], tuple(size), out)
            np.testing.assert_array_equal(got[index], expected)
