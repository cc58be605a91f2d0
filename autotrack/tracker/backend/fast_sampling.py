"""`sampling`'s search patches and scale samples with the area shrink in compiled kernels (the
fast backend): OpenCV's generic INTER_AREA computed exactly (tests/test_area_resample.py), the
33 scale samples in one call; the other cases go to `sampling` itself."""

from __future__ import annotations

import math

import numpy as np

from autotrack.tracker.backend.area_resample import (
    area_path_is_generic,
    area_paths_are_generic,
    area_resize_crop,
    area_resize_crops,
)
from autotrack.tracker.sampling import crop_replicate, resize_auto


def search_patch(
    image: np.ndarray,
    position: tuple[float, float],
    region_size_hw: tuple[int, int],
    output_size_hw: tuple[int, int],
) -> np.ndarray:
    """The search region around `position` resampled to the filter's fixed patch size."""
    region = (max(int(region_size_hw[0]), 1), max(int(region_size_hw[1]), 1))
    output = (int(output_size_hw[0]), int(output_size_hw[1]))
    if area_path_is_generic(region, output):  # OpenCV's generic area shrink, computed exactly
        top = math.floor(position[0]) - region[0] // 2
        left = math.floor(position[1]) - region[1] // 2
        return area_resize_crop(image, top, left, region, output)
    patch = crop_replicate(image, position, region_size_hw)
    return resize_auto(patch, output_size_hw)  # cv2 reads the strided view, no copy


def sized_patches(
    image: np.ndarray,
    position: tuple[float, float],
    sizes: np.ndarray,
    model_size_hw: tuple[int, int],
) -> np.ndarray:
    """Patches of the given (N, 2) integer (rows, cols) sizes centred on `position`, each resized
    to the model size: (N, rows, cols[, 3]): `sampling.sized_patches`, the ones OpenCV shrinks
    with its generic area tables (nearly all) computed together, bit for bit."""
    model = (int(model_size_hw[0]), int(model_size_hw[1]))
    generic = area_paths_are_generic(sizes, model)
    tops = math.floor(position[0]) - sizes[:, 0] // 2
    lefts = math.floor(position[1]) - sizes[:, 1] // 2
    if generic.all():  # the usual case: one kernel call, no copy
        return area_resize_crops(image, tops, lefts, sizes, model)
    samples = np.empty((len(sizes), *model, *image.shape[2:]), np.uint8)
    if generic.any():
        samples[generic] = area_resize_crops(
            image, tops[generic], lefts[generic], sizes[generic], model
        )
    for index in np.flatnonzero(~generic):
        patch = crop_replicate(image, position, (int(sizes[index, 0]), int(sizes[index, 1])))
        samples[index] = resize_auto(patch, model)
    return samples
