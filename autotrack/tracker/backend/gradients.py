"""gradMag's per-pixel gradients and gradHist's histogram, as Piotr Dollar's toolbox computes
them for `fhog`.

`gradient2`'s centred differences (one-sided, factor 1, at the image border) on float32 planes,
the choice, per pixel, of the channel with the largest squared magnitude (a later channel
only if strictly larger), and the orientation histogram of the cells (`gradient_histogram`),
which `fhog` normalises.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_HALF = np.float32(0.5)
_ONE = np.float32(1.0)
_MINUS_ONE = np.float32(-1.0)
_BORDER_GAIN = np.float32(8.0) / np.float32(7.0)
_ZERO_GRADIENT_INVERSE = np.float32(1e10)  # min(rsqrt(0), 1e10) in gradMag
ACOS_STEPS = 10000  # the toolbox's acosTable: a[i] ~= acos(i / 10000)
ACOS_PAD = 10
ACOS_OFFSET = ACOS_STEPS + ACOS_PAD


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def planar_float32(images):
    """(N, H, W, C) of any real dtype -> C-contiguous float32 (C, H, N W), as `single(I)` does,
    the N images side by side (one image: N = 1)."""
    count, height, width, channels = images.shape
    planes = np.empty((channels, height, count * width), np.float32)
    if channels == 3:  # the common RGB case, written so that LLVM vectorises the deinterleave
        flat = images.reshape(count, height, width * 3)
        for i in range(count):
            first = i * width
            for y in range(height):
                row = flat[i, y]
                red = planes[0, y, first : first + width]
                green = planes[1, y, first : first + width]
                blue = planes[2, y, first : first + width]
                for x in range(width):
                    red[x] = np.float32(row[3 * x])
                    green[x] = np.float32(row[3 * x + 1])
                    blue[x] = np.float32(row[3 * x + 2])
    else:
        for i in range(count):
            first = i * width
            for y in range(height):
                for c in range(channels):
                    source = images[i, y, :, c]
                    target = planes[c, y, first : first + width]
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


def strongest_gradients(planes: np.ndarray, rows: int, cols: int, sample_width: int) -> np.ndarray:
    """gradMag's choice of channel: per pixel of the first `rows` x `cols`, the x and y
    gradients of the channel with the largest squared magnitude (a later channel only if
    strictly larger) and that magnitude, as one float32 (3, rows, cols) array.

    Three channels (RGB, the usual case) choose in registers and store every element once; other
    counts choose into scratch rows and copy back. Neither updates a running best in place:
    LLVM reads `gx[x] = cx if larger else gx[x]` as a store only where `larger` holds and
    vectorises it with masked stores (vmaskmovps), which AMD's Zen cores run at a fraction of a
    plain store's rate (1.5x slower on RGB search patches; `benchmarks/kernel_asm.py` lists any
    kernel that has them). The comparisons and products are the same throughout. The two are
    kernels of their own: a video compiles only the one its frames need. The whole image in
    one call: a call a row cost more than the work on the scale filter's small
    samples. A grey image has no choice to make: its gradients and their squared magnitude.
    Images side by side, `sample_width` columns each, take their gradients as `row_gradients`
    does.
    """
    if planes.shape[0] == 3:
        return _rgb_gradients(planes, rows, cols, sample_width)
    return _any_channel_gradients(planes, rows, cols, sample_width)


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _rgb_gradients(planes, rows, cols, sample_width):
    """`strongest_gradients` of three planes: the choice in registers."""
    gradients = np.empty((3, rows, cols), np.float32)
    gx, gy, squared = gradients[0], gradients[1], gradients[2]
    scratch = np.empty((6, cols), np.float32)  # one row's x and y gradients of each channel
    gx0, gy0, gx1, gy1 = scratch[0], scratch[1], scratch[2], scratch[3]
    gx2, gy2 = scratch[4], scratch[5]
    for y in range(rows):
        row_gx, row_gy, row_squared = gx[y], gy[y], squared[y]
        row_gradients(planes[0], y, gx0, gy0, sample_width)
        row_gradients(planes[1], y, gx1, gy1, sample_width)
        row_gradients(planes[2], y, gx2, gy2, sample_width)
        for x in range(cols):
            best_x, best_y = gx0[x], gy0[x]
            best = best_x * best_x + best_y * best_y
            best, best_x, best_y = _stronger(best, best_x, best_y, gx1[x], gy1[x])
            best, best_x, best_y = _stronger(best, best_x, best_y, gx2[x], gy2[x])
            row_squared[x], row_gx[x], row_gy[x] = best, best_x, best_y
    return gradients


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _any_channel_gradients(planes, rows, cols, sample_width):
    """`strongest_gradients` of any number of planes: the first channel's gradients, then each
    later channel's choice into scratch rows, copied back (a grey image: its gradients)."""
    channels = planes.shape[0]
    gradients = np.empty((3, rows, cols), np.float32)
    gx, gy, squared = gradients[0], gradients[1], gradients[2]
    scratch = np.empty((5, cols), np.float32)  # a channel's row, then the chosen values
    gx0, gy0, gx1, gy1, chosen_squared = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4]
    for y in range(rows):
        row_gx, row_gy, row_squared = gx[y], gy[y], squared[y]
        row_gradients(planes[0], y, row_gx, row_gy, sample_width)
        for x in range(cols):
            row_squared[x] = row_gx[x] * row_gx[x] + row_gy[x] * row_gy[x]
        for c in range(1, channels):
            row_gradients(planes[c], y, gx0, gy0, sample_width)
            for x in range(cols):
                chosen_squared[x], gx1[x], gy1[x] = _stronger(
                    row_squared[x], row_gx[x], row_gy[x], gx0[x], gy0[x]
                )
            for x in range(cols):
                row_squared[x] = chosen_squared[x]
                row_gx[x] = gx1[x]
                row_gy[x] = gy1[x]
    return gradients


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _bin_coordinates(n_pixels, cell):
    """Per pixel: left/top cell index (-1 before the first centre) and fractional offset.

    Accumulates (i + 0.5) / cell - 0.5 in float32 exactly as gradHist does.
    """
    first = np.empty(n_pixels, np.int64)
    frac = np.empty(n_pixels, np.float32)
    step = _ONE / np.float32(cell)
    position = _HALF * step - _HALF
    for i in range(n_pixels):
        index = -1 if i < cell // 2 else int(position)
        first[i] = index
        frac[i] = position - np.float32(index)
        position += step
    return first, frac


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _scatter_row(
    flat,
    weight,
    orient,
    x_first,
    x_frac,
    start,
    first_cell,
    sample_cells,
    y0,
    yd,
    top,
    hb,
    wb,
    used,
):
    """gradHist's bilinear vote in space of one image's `used` pixels of a row (from column
    `start` of the row's `weight`, magnitude / cell^2, and `orient`, the bin's plane offset)
    into the flat (bins, hb, wb) histogram, where the image's `sample_cells` cells of a row
    start at column `first_cell`. Unsigned indices: no negative-index wraparound code."""
    top = top + first_cell  # flat index of hist[0, y0, first_cell]
    for within in range(used):
        m = weight[start + within]
        o = orient[start + within]
        x0 = x_first[within]
        xd = x_frac[within]
        xyd = xd * yd
        w00 = _ONE - xd - yd + xyd
        w10 = yd - xyd
        w01 = xd - xyd
        w11 = xyd
        has_left = x0 >= 0
        has_right = x0 < sample_cells - 1
        at = top + x0 + o  # hist[o, y0, x0] (o: the bin's plane offset); right cell: + 1
        if y0 < 0:  # leading rows: only the cell row below the first centre line
            if has_left:
                flat[np.uint64(at + wb)] += w10 * m
            if has_right:
                flat[np.uint64(at + wb + 1)] += w11 * m
        elif y0 < hb - 1:
            if has_left:
                flat[np.uint64(at)] += w00 * m
                flat[np.uint64(at + wb)] += w10 * m
            if has_right:
                flat[np.uint64(at + 1)] += w01 * m
                flat[np.uint64(at + wb + 1)] += w11 * m
        else:  # final rows: no cell row below
            if has_left:
                flat[np.uint64(at)] += w00 * m
            if has_right:
                flat[np.uint64(at + 1)] += w01 * m


def histogram_extent(hist_shape, cell, sample_width, sample_cells):
    """The pixel rows and columns `gradient_histogram` bins for a (bins, hb, wb) histogram of
    images side by side (`sample_width` pixel and `sample_cells` cell columns each): the
    gradients `strongest_gradients` computes for it."""
    hb, wb = hist_shape[1], hist_shape[2]
    samples = wb // sample_cells
    return hb * cell, (samples - 1) * sample_width + sample_cells * cell


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def gradient_histogram(gradients, cell, n_bins, bins, hist, sample_width, sample_cells):
    """gradMag (full orientation) + gradHist(softBin=-1): bilinear in space, hard in angle.

    `gradients` is `strongest_gradients` of the image (gx, gy and squared magnitude, float32
    (3, rows, cols) for `histogram_extent`), `bins` `orientation_bins(n_bins // 2)`, `hist`
    C-contiguous zeros (>= n_bins, hb, wb), channel-major: a pixel's right cell is the next
    float, not n_bins on. The image may be several side by side, `sample_width` columns each,
    whose histograms `hist` then holds side by side, `sample_cells` columns each (one image: its
    width and wb): each image's gradients, cells and borders are its own, and every cell sums
    its pixels in the same order as for the image alone, so the same bits; the rows of all
    the images run as one long row.
    Row by row in small vectorisable passes, branch-free where the data decide (random gradient
    signs would defeat branch prediction); the scatter indexes the flat histogram with unsigned
    indices (no negative-index wraparound code per access).
    """
    hb, wb = hist.shape[1], hist.shape[2]
    rows = hb * cell
    inv_cell2 = _ONE / np.float32(cell) / np.float32(cell)
    unit = np.float32(ACOS_STEPS)
    zero = np.float32(0.0)
    samples = wb // sample_cells
    used = sample_cells * cell  # an image's columns that fill whole cells
    cols = (samples - 1) * sample_width + used
    x_first, x_frac = _bin_coordinates(used, cell)
    y_first, y_frac = _bin_coordinates(rows, cell)
    table_index = np.empty(cols, np.uint32)
    weight = np.empty(cols, np.float32)
    orient = np.empty(cols, np.int64)
    flat = hist.reshape(-1)
    plane = hb * wb
    for y in range(rows):
        gx, gy, squared = gradients[0, y], gradients[1, y], gradients[2, y]
        for x in range(cols):
            magnitude = np.float32(math.sqrt(squared[x]))
            inverse = min(_ONE / magnitude, _ZERO_GRADIENT_INVERSE)
            negative = gy[x] < zero
            # acos of the unit x-gradient, sign-flipped for negative y, via the toolbox's table;
            # `bins` adds pi for negative y (its second half), mapping the angle to [0, 2 pi),
            # and rounds it to a bin. (atan2 would differ at bin edges only.)
            sign = _MINUS_ONE if negative else _ONE
            index = np.int32(gx[x] * inverse * unit * sign) + ACOS_OFFSET
            table_index[x] = index + (2 * ACOS_OFFSET if negative else 0)
            weight[x] = magnitude * inv_cell2
        for x in range(cols):
            orient[x] = np.int64(bins[table_index[x]]) * plane
        y0 = y_first[y]
        yd = y_frac[y]
        top = y0 * wb  # flat index of hist[0, y0, 0]
        if samples == 1:  # its own call: inside the loop below, one image runs ~6% slower
            _scatter_row(flat, weight, orient, x_first, x_frac, 0, 0, wb, y0, yd, top, hb, wb, used)
        else:  # image by image: the scatter is scalar code, and each image's cells its own
            for sample in range(samples):
                start, first_cell = sample * sample_width, sample * sample_cells
                _scatter_row(
                    flat,
                    weight,
                    orient,
                    x_first,
                    x_frac,
                    start,
                    first_cell,
                    sample_cells,
                    y0,
                    yd,
                    top,
                    hb,
                    wb,
                    used,
                )
    # Border cells only receive 7/8 of an interior cell's weight (gradHist, softBin odd).
    for o in range(n_bins):
        for first in range(0, wb, sample_cells):
            last = first + sample_cells - 1
            for y in range(hb):
                hist[o, y, first] *= _BORDER_GAIN
            for x in range(first, last + 1):
                hist[o, 0, x] *= _BORDER_GAIN
            for y in range(hb):
                hist[o, y, last] *= _BORDER_GAIN
            for x in range(first, last + 1):
                hist[o, hb - 1, x] *= _BORDER_GAIN
