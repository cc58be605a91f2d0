"""gradMag's per-pixel gradients, as Piotr Dollar's toolbox computes them for `fhog`.

`gradient2`'s centred differences (one-sided, factor 1, at the image border) on float32 planes,
and the choice, per pixel, of the channel with the largest squared magnitude (a later channel
only if strictly larger). `fhog` bins what these return.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_HALF = np.float32(0.5)
_ONE = np.float32(1.0)


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def planar_float32(image):
    """(H, W, C) of any real dtype -> C-contiguous float32 (C, H, W), as `single(I)` does."""
    height, width, channels = image.shape
    planes = np.empty((channels, height, width), np.float32)
    if channels == 3:  # the common RGB case, written so that LLVM vectorises the deinterleave
        flat = image.reshape(height, width * 3)
        for y in range(height):
            row = flat[y]
            red, green, blue = planes[0, y], planes[1, y], planes[2, y]
            for x in range(width):
                red[x] = np.float32(row[3 * x])
                green[x] = np.float32(row[3 * x + 1])
                blue[x] = np.float32(row[3 * x + 2])
    else:
        for y in range(height):
            for c in range(channels):
                source = image[y, :, c]
                target = planes[c, y]
                for x in range(width):
                    target[x] = np.float32(source[x])
    return planes


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def row_gradients(plane, y, gx, gy, sample_width):
    """gradient2 on one row: centred differences, one-sided with factor 1 at the image border.

    `plane` may hold several images side by side, each `sample_width` columns wide (the
    image's own width for one): every image's first and last columns are then one-sided too.
    Written with offset views so every loop index is a plain range index (vectorisable).
    """
    height, width = plane.shape
    cols = gx.size
    up = y - 1 if y > 0 else 0
    down = y + 1 if y < height - 1 else height - 1
    y_scale = _HALF if (y > 0 and y < height - 1) else _ONE
    above, below, row = plane[up], plane[down], plane[y]
    for x in range(cols):
        gy[x] = (below[x] - above[x]) * y_scale
    inner = min(cols, width - 1) - 1  # columns 1..inner have both neighbours
    ahead, behind, centre = row[2 : 2 + inner], row[:inner], gx[1 : 1 + inner]
    for i in range(inner):
        centre[i] = (ahead[i] - behind[i]) * _HALF
    gx[0] = row[1] - row[0]
    if cols == width:
        gx[cols - 1] = row[width - 1] - row[width - 2]
    if sample_width < cols:  # images side by side: each one's own borders
        _sample_borders(row, gx, sample_width)


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _sample_borders(row, gx, sample_width):
    """One-sided x-gradients at the first and last column of each image after the first, for
    images side by side `sample_width` columns each (`row_gradients` did the outer borders)."""
    for start in range(sample_width, gx.size, sample_width):
        gx[start] = row[start + 1] - row[start]
        gx[start - 1] = row[start - 1] - row[start - 2]


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _stronger(best, best_x, best_y, candidate_x, candidate_y):
    """(squared magnitude, gx, gy) of the candidate gradient if its squared magnitude is strictly
    larger than `best`, else of the best so far. Every value is loaded before the call: a load
    only one side of the choice used would be masked too."""
    candidate = candidate_x * candidate_x + candidate_y * candidate_y
    larger = candidate > best
    if larger:
        return candidate, candidate_x, candidate_y
    return best, best_x, best_y


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def strongest_gradients(planes, rows, cols, sample_width):
    """gradMag's choice of channel: per pixel of the first `rows` x `cols`, the x and y
    gradients of the channel with the largest squared magnitude (a later channel only if
    strictly larger) and that magnitude, as three float32 (rows, cols) arrays.

    Three channels (RGB, the usual case) choose in registers and store every element once; other
    counts choose into scratch rows and copy back. Neither updates a running best in place:
    LLVM reads `gx[x] = cx if larger else gx[x]` as a store only where `larger` holds and
    vectorises it with masked stores (vmaskmovps), which AMD's Zen cores run at a fraction of a
    plain store's rate (1.5x slower on RGB search patches; `benchmarks/kernel_asm.py` lists any
    kernel that has them). The comparisons and products are the same throughout. The
    whole image in one call: a call a row cost more than the work on the scale filter's small
    samples. A grey image has no choice to make and is not passed (`rows` = 0). Images side by
    side, `sample_width` columns each, take their gradients as `row_gradients` does.
    """
    channels = planes.shape[0]
    gradients = np.empty((3, rows, cols), np.float32)
    gx, gy, squared = gradients[0], gradients[1], gradients[2]
    scratch = np.empty((7, cols), np.float32)  # one row's x and y gradients of each channel
    gx0, gy0, gx1, gy1 = scratch[0], scratch[1], scratch[2], scratch[3]
    gx2, gy2, chosen_squared = scratch[4], scratch[5], scratch[6]
    for y in range(rows):
        row_gx, row_gy, row_squared = gx[y], gy[y], squared[y]
        if channels == 3:
            row_gradients(planes[0], y, gx0, gy0, sample_width)
            row_gradients(planes[1], y, gx1, gy1, sample_width)
            row_gradients(planes[2], y, gx2, gy2, sample_width)
            for x in range(cols):
                best_x, best_y = gx0[x], gy0[x]
                best = best_x * best_x + best_y * best_y
                best, best_x, best_y = _stronger(best, best_x, best_y, gx1[x], gy1[x])
                best, best_x, best_y = _stronger(best, best_x, best_y, gx2[x], gy2[x])
                row_squared[x], row_gx[x], row_gy[x] = best, best_x, best_y
            continue
        row_gradients(planes[0], y, row_gx, row_gy, sample_width)
        for x in range(cols):
            row_squared[x] = row_gx[x] * row_gx[x] + row_gy[x] * row_gy[x]
        for c in range(1, channels):  # another count: the choice into scratch, then copied
            row_gradients(planes[c], y, gx0, gy0, sample_width)
            for x in range(cols):
                chosen_squared[x], gx1[x], gy1[x] = _stronger(
                    row_squared[x], row_gx[x], row_gy[x], gx0[x], gy0[x]
                )
            for x in range(cols):
                row_squared[x] = chosen_squared[x]
                row_gx[x] = gx1[x]
                row_gy[x] = gy1[x]
    return gx, gy, squared
