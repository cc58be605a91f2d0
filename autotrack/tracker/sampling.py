"""Image sampling: square search patches and scale samples, border pixels replicated.

Positions are the release's 1-based (row, col) pixel coordinates; patches are resampled with
OpenCV as the release's mexResize 'auto' does (area averaging when shrinking, bilinear when
enlarging).
"""

from __future__ import annotations

import math

import cv2
import numpy as np


def resize_auto(patch: np.ndarray, size_hw: tuple[int, int]) -> np.ndarray:
    """Resize to (rows, cols): INTER_AREA when the area shrinks, INTER_LINEAR otherwise."""
    rows, cols = int(size_hw[0]), int(size_hw[1])
    if patch.shape[0] == rows and patch.shape[1] == cols:
        return patch
    shrinking = rows * cols < patch.shape[0] * patch.shape[1]
    interpolation = cv2.INTER_AREA if shrinking else cv2.INTER_LINEAR
    return cv2.resize(patch, (cols, rows), interpolation=interpolation)


def crop_replicate(
    image: np.ndarray, position: tuple[float, float], size_hw: tuple[int, int]
) -> np.ndarray:
    """Patch of `size_hw` centred on the 1-based `position`, pixels outside copied from the border.

    Equivalent to the release's index clamping `xs = floor(pos) + (1:sz) - floor(sz/2)`.
    """
    rows, cols = max(int(size_hw[0]), 1), max(int(size_hw[1]), 1)
    height, width = image.shape[:2]
    top = math.floor(position[0]) - rows // 2  # 0-based first row
    left = math.floor(position[1]) - cols // 2
    bottom, right = top + rows, left + cols
    if top >= 0 and left >= 0 and bottom <= height and right <= width:
        return image[top:bottom, left:right]
    if top < height and bottom > 0 and left < width and right > 0:
        inside = np.ascontiguousarray(
            image[max(top, 0) : min(bottom, height), max(left, 0) : min(right, width)]
        )
        return cv2.copyMakeBorder(
            inside,
            max(-top, 0),
            max(bottom - height, 0),
            max(-left, 0),
            max(right - width, 0),
            cv2.BORDER_REPLICATE,
        )
    # Entirely outside the image (a target that left the frame): every pixel is a border one.
    row_index = np.clip(np.arange(top, bottom), 0, height - 1)
    col_index = np.clip(np.arange(left, right), 0, width - 1)
    return image[row_index[:, None], col_index[None, :]]


def search_patch(
    image: np.ndarray,
    position: tuple[float, float],
    region_size_hw: tuple[int, int],
    output_size_hw: tuple[int, int],
) -> np.ndarray:
    """The search region around `position` resampled to the filter's fixed patch size."""
    return resize_auto(crop_replicate(image, position, region_size_hw), output_size_hw)


def sized_patches(
    image: np.ndarray,
    position: tuple[float, float],
    sizes: np.ndarray,
    model_size_hw: tuple[int, int],
) -> np.ndarray:
    """Patches of the (N, 2) integer (rows, cols) sizes centred on `position`, each resized to
    the model size: (N, rows, cols[, 3]) (the scale samples, with `scale_sizes`)."""
    return np.stack(
        [
            resize_auto(crop_replicate(image, position, (int(rows), int(cols))), model_size_hw)
            for rows, cols in sizes
        ]
    )


def scale_sizes(base_target_size_hw: np.ndarray, scale_factors: np.ndarray) -> np.ndarray:
    """(N, 2) integer (rows, cols) of the target at each scale factor (at least 2 pixels)."""
    factors = np.asarray(scale_factors, dtype=np.float64)
    base = np.asarray(base_target_size_hw, dtype=np.float64)
    return np.maximum(np.floor(base[None, :] * factors[:, None]), 2).astype(np.int64)
