"""fHOG's compiled kernels (see `fhog` for the feature and the public functions).

All of them live in this one module: numba's on-disk cache of a kernel holds the kernels it
calls compiled into it, and notices a change of its own source file only, so a kernel calling
one from another module would keep running the old code after that module changed.

Stage one is the toolbox's `gradMag` + `gradHist(softBin = -1)`: per pixel the strongest
channel's gradient, its orientation bin through the acos table, and its magnitude spread
bilinearly over the four nearest cells. Bit for bit the toolbox's float32 operations (as ported
in round 1), computed faster since round 9:
- the orientation: the acos table's angle, plus pi for a negative y-gradient, times the bins
  per radian, rounded to a bin: a function of the table index and the sign alone, so it is
  read from `fhog.orientation_bins`, a small integer table of that same float32 arithmetic
  done once per entry, instead of a float gather and three operations per pixel;
- the histogram: every cell bin receives its float32 additions in the same order as before
  (pixel by pixel, row-major); the products (bilinear weight x magnitude) are taken in
  vectorised passes over the row; the scatter runs over the row's interior without per-pixel
  edge tests (the edge pixels, with no left or no right cell, apart), two neighbouring pixels
  of a cell at a time, a sum into a bin both pixels hit handed on in a register.
Stage two (`hogNormMatrix`, `hogChannels`) normalises the cells along whole cell rows.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_PI = np.float32(3.14159265)  # the toolbox's PI (a float literal)
_ACOS_STEPS = 10000  # acosTable: a[i] ~= acos(i / 10000)
_ACOS_PAD = 10
_ACOS_OFFSET = _ACOS_STEPS + _ACOS_PAD
_ACOS_ENTRIES = 2 * _ACOS_OFFSET
_HALF = np.float32(0.5)
_ONE = np.float32(1.0)
_BORDER_GAIN = np.float32(8.0) / np.float32(7.0)
_ZERO_GRADIENT_INVERSE = np.float32(1e10)  # min(rsqrt(0), 1e10) in gradMag
_TEXTURE_WEIGHT = np.float32(0.2357)  # ~ 1 / sqrt(18), hogChannels' r


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
def _row_gradients(plane, y, gx, gy):
    """gradient2 on one row: centred differences, one-sided with factor 1 at the image border.

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


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _interior_pairs(first, last_cell):
    """(lo, hi, starts): pixels lo..hi-1 have a cell on both sides (0 <= first[x] < last_cell),
    those before lo no left cell, those from hi no right one (`first` is non-decreasing).
    `starts` lists the interior's pixels in order, taken two at a time where two neighbours
    share their cells (a pair) and one at a time where they do not: entry x >= 0 is the pair
    (x, x + 1), entry -1 - x the single pixel x."""
    lo = 0
    while lo < first.size and first[lo] < 0:
        lo += 1
    hi = lo
    while hi < first.size and first[hi] < last_cell:
        hi += 1
    starts = np.empty(max(hi - lo, 0), np.int64)
    count = 0
    x = lo
    while x < hi:
        if x + 1 < hi and first[x + 1] == first[x]:
            starts[count] = x
            x += 2
        else:
            starts[count] = -1 - x
            x += 1
        count += 1
    return lo, hi, starts[:count]


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _add_pair(flat, first, second, share_first, share_second):
    """flat[first] += share_first, then flat[second] += share_second, with the first sum
    handed on in a register when both are the same bin (no store-to-load round trip)."""
    before_first = flat[first]
    before_second = flat[second]
    after_first = before_first + share_first
    after_second = (after_first if first == second else before_second) + share_second
    flat[first] = after_first
    flat[second] = after_second


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _scatter_edge(flat, top, bottom, step, start, stop, position, left, right, shares, side):
    """The edge pixels start..stop-1 (side -1: no left cell, +1: no right cell), in order;
    `bottom` < 0 when there is no cell row below."""
    for x in range(start, stop):
        at = position[x]
        if side > 0:
            flat[np.uint64(top + at)] += left[shares, x]
            if bottom >= 0:
                flat[np.uint64(bottom + at)] += left[shares + 1, x]
        else:
            flat[np.uint64(top + at + step)] += right[shares, x]
            if bottom >= 0:
                flat[np.uint64(bottom + at + step)] += right[shares + 1, x]


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _scatter_interior(flat, top, bottom, step, starts, position, left, right, shares):
    """hist[row, x0, o] += the interior pixels' products, pixel by pixel (`_interior_pairs`):
    a pair's two pixels share their four cells, so their eight additions touch each of those
    bins in pixel order whatever the order among bins."""
    two_rows = bottom >= 0
    for entry in starts:
        if entry >= 0:
            x = entry
            a, b = position[x], position[x + 1]
            _add_pair(
                flat, np.uint64(top + a), np.uint64(top + b), left[shares, x], left[shares, x + 1]
            )
            _add_pair(
                flat,
                np.uint64(top + a + step),
                np.uint64(top + b + step),
                right[shares, x],
                right[shares, x + 1],
            )
            if two_rows:
                _add_pair(
                    flat,
                    np.uint64(bottom + a),
                    np.uint64(bottom + b),
                    left[shares + 1, x],
                    left[shares + 1, x + 1],
                )
                _add_pair(
                    flat,
                    np.uint64(bottom + a + step),
                    np.uint64(bottom + b + step),
                    right[shares + 1, x],
                    right[shares + 1, x + 1],
                )
        else:
            x = -1 - entry
            at = position[x]
            flat[np.uint64(top + at)] += left[shares, x]
            flat[np.uint64(top + at + step)] += right[shares, x]
            if two_rows:
                flat[np.uint64(bottom + at)] += left[shares + 1, x]
                flat[np.uint64(bottom + at + step)] += right[shares + 1, x]


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def gradient_histogram(planes, cell, bins, hist):
    """gradMag (full orientation) + gradHist(softBin=-1): bilinear in space, hard in angle,
    into the zeroed C-contiguous float32 `hist` (hb, wb, n_bins).

    `planes` is float32 (C, H, W), `bins` is `orientation_bins(n_bins // 2)`. Row by row in
    small vectorisable passes, branch-free where the data decide.
    """
    channels = planes.shape[0]
    hb, wb, n_bins = hist.shape
    rows, cols = hb * cell, wb * cell
    inv_cell2 = _ONE / np.float32(cell) / np.float32(cell)
    unit = np.float32(_ACOS_STEPS)
    zero = np.float32(0.0)
    x_first, x_frac = _bin_coordinates(cols, cell)
    y_first, y_frac = _bin_coordinates(rows, cell)
    lo, hi, starts = _interior_pairs(x_first, wb - 1)
    flat = hist.reshape(-1)
    row_size = wb * n_bins
    gx = np.empty(cols, np.float32)
    gy = np.empty(cols, np.float32)
    squared = np.empty(cols, np.float32)
    channel_gx = np.empty(cols, np.float32)
    channel_gy = np.empty(cols, np.float32)
    table_index = np.empty(cols, np.int64)
    weight = np.empty(cols, np.float32)
    position = np.empty(cols, np.int64)
    left = np.empty((2, cols), np.float32)  # the left cell's share, cell row y0 and y0 + 1
    right = np.empty((2, cols), np.float32)
    for y in range(rows):
        _row_gradients(planes[0], y, gx, gy)
        for x in range(cols):
            squared[x] = gx[x] * gx[x] + gy[x] * gy[x]
        for c in range(1, channels):  # keep the channel of largest magnitude (strictly larger)
            _row_gradients(planes[c], y, channel_gx, channel_gy)
            for x in range(cols):  # unconditional stores of selects: this form vectorises
                cx, cy, best = channel_gx[x], channel_gy[x], squared[x]
                candidate = cx * cx + cy * cy
                larger = candidate > best
                squared[x] = candidate if larger else best
                gx[x] = cx if larger else gx[x]
                gy[x] = cy if larger else gy[x]
        for x in range(cols):
            magnitude = np.float32(math.sqrt(squared[x]))
            inverse = min(_ONE / magnitude, _ZERO_GRADIENT_INVERSE)
            negative = gy[x] < zero
            # acos of the unit x-gradient, sign-flipped for negative y, via the toolbox's table;
            # `bins` adds pi for negative y (its second half) and rounds the angle to a bin.
            sign = -_ONE if negative else _ONE
            index = np.int32(gx[x] * inverse * unit * sign) + _ACOS_OFFSET
            table_index[x] = index + (_ACOS_ENTRIES if negative else 0)
            weight[x] = magnitude * inv_cell2
        for x in range(cols):
            position[x] = x_first[x] * n_bins + np.int64(bins[table_index[x]])
        yd = y_frac[y]
        for x in range(cols):
            xd = x_frac[x]
            m = weight[x]
            xyd = xd * yd
            left[0, x] = (_ONE - xd - yd + xyd) * m
            left[1, x] = (yd - xyd) * m
            right[0, x] = (xd - xyd) * m
            right[1, x] = xyd * m
        y0 = y_first[y]
        if y0 < 0:  # leading rows: only the cell row below the first centre line
            top, bottom, shares = 0, -1, 1
        elif y0 < hb - 1:
            top, bottom, shares = y0 * row_size, (y0 + 1) * row_size, 0
        else:  # final rows: no cell row below
            top, bottom, shares = y0 * row_size, -1, 0
        _scatter_edge(flat, top, bottom, n_bins, 0, lo, position, left, right, shares, -1)
        _scatter_interior(flat, top, bottom, n_bins, starts, position, left, right, shares)
        _scatter_edge(flat, top, bottom, n_bins, hi, cols, position, left, right, shares, 1)
    # Border cells only receive 7/8 of an interior cell's weight (gradHist, softBin odd).
    for o in range(n_bins):
        for y in range(hb):
            hist[y, 0, o] *= _BORDER_GAIN
        for x in range(wb):
            hist[0, x, o] *= _BORDER_GAIN
        for y in range(hb):
            hist[y, wb - 1, o] *= _BORDER_GAIN
        for x in range(wb):
            hist[hb - 1, x, o] *= _BORDER_GAIN


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _block_normalisers(insensitive, cell):
    """hogNormMatrix: 1/sqrt(2x2 block energy + eps) on an (hb+1, wb+1) grid, border copied.

    Entry [i+1, j+1] belongs to the block whose top-left cell is (i, j). The border is filled in
    the C code's order, which matters only when hb or wb is 1 (then raw energies leak through,
    as in the toolbox).
    """
    hb, wb, n_orients = insensitive.shape
    norm = np.zeros((hb + 1, wb + 1), np.float32)
    for o in range(n_orients):
        for y in range(hb):
            for x in range(wb):
                value = insensitive[y, x, o]
                norm[y + 1, x + 1] += value * value
    eps = np.float32(1e-4) / np.float32(4.0)
    for _ in range(4):
        eps = eps / np.float32(cell)
    for x in range(wb - 1):
        for y in range(hb - 1):
            total = (
                norm[y + 1, x + 1] + norm[y + 2, x + 1] + norm[y + 1, x + 2] + norm[y + 2, x + 2]
            ) + eps
            norm[y + 1, x + 1] = _ONE / np.float32(math.sqrt(total))
    last_x, last_y = wb, hb
    norm[0, 0] = norm[1, 1]
    for y in range(hb + 1):
        norm[y, 0] = norm[y, 1]
    norm[last_y, 0] = norm[last_y - 1, 1]
    norm[0, last_x] = norm[1, last_x - 1]
    for y in range(hb + 1):
        norm[y, last_x] = norm[y, last_x - 1]
    norm[last_y, last_x] = norm[last_y - 1, last_x - 1]
    for x in range(wb + 1):
        norm[0, x] = norm[1, x]
    for x in range(wb + 1):
        norm[last_y, x] = norm[last_y - 1, x]
    return norm


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _normalised_row(by_channel, o, quad, clip, row_weights, values, sums, texture):
    """One cell row of orientation channel o (hogChannels): the mean of each cell's value
    under its four block normalisers `quad` (4, cols), each clipped, times `row_weights`, into
    `values[o]`; with `texture`, the clipped values times the texture weight are added to
    `sums` (4, cols). Inlined, plain indexing of C-contiguous rows (vectorised), no array
    views: a call or a view per row costs reference counting, which on the scale filter's
    6 x 4-cell samples was most of the time."""
    for x in range(by_channel.shape[1]):
        r = by_channel[o, x]
        # The four blocks containing the cell: hogChannels' GETT(0), (1), (hb1), (hb1+1).
        t0 = min(r * quad[0, x], clip)
        t1 = min(r * quad[1, x], clip)
        t2 = min(r * quad[2, x], clip)
        t3 = min(r * quad[3, x], clip)
        values[o, x] = (t0 * _HALF + t1 * _HALF + t2 * _HALF + t3 * _HALF) * row_weights[x]
        if texture:
            sums[0, x] += t0 * _TEXTURE_WEIGHT
            sums[1, x] += t1 * _TEXTURE_WEIGHT
            sums[2, x] += t2 * _TEXTURE_WEIGHT
            sums[3, x] += t3 * _TEXTURE_WEIGHT


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _fhog_into(image, cell, n_orients, clip, bins, weights, out):
    """fhog of one (H, W, C) image, each cell's values times `weights[y, x]`, into `out`
    (>= 3n+4, H//cell, W//cell), channel-first, any strides (a channel-first slice of a
    transform's input buffer, or a transposed view of a channel-last array); channels past
    3n+4 (the toolbox's zero channel) are left as they are.

    A float32 product rounds once wherever it is taken, so `out` holds exactly what the
    unweighted features times the weights would give (weights of one give the features). The
    normalisation runs along whole cell rows, one channel at a time, each texture sum still
    taken over the orientations in the toolbox's order.
    """
    hb, wb = out.shape[1], out.shape[2]
    if hb == 0 or wb == 0:
        return
    n_bins = 2 * n_orients
    sensitive = np.zeros((hb, wb, n_bins), np.float32)
    gradient_histogram(planar_float32(image), cell, bins, sensitive)
    insensitive = np.empty((hb, wb, n_orients), np.float32)
    for y in range(hb):
        for x in range(wb):
            for o in range(n_orients):
                insensitive[y, x, o] = sensitive[y, x, o] + sensitive[y, x, o + n_orients]
    norm = _block_normalisers(insensitive, cell)
    texture_first = 3 * n_orients
    by_channel = np.empty((n_bins + n_orients, wb), np.float32)  # one cell row, channel-major
    values = np.empty((n_bins + n_orients, wb), np.float32)
    quad = np.empty((4, wb), np.float32)
    row_weights = np.empty(wb, np.float32)
    sums = np.empty((4, wb), np.float32)
    for y in range(hb):
        for x in range(wb):
            for o in range(n_bins):
                by_channel[o, x] = sensitive[y, x, o]
            for o in range(n_orients):
                by_channel[n_bins + o, x] = insensitive[y, x, o]
            quad[0, x] = norm[y + 1, x + 1]
            quad[1, x] = norm[y, x + 1]
            quad[2, x] = norm[y + 1, x]
            quad[3, x] = norm[y, x]
            row_weights[x] = weights[y, x]
        for k in range(4):
            for x in range(wb):
                sums[k, x] = 0.0
        for o in range(n_bins + n_orients):
            _normalised_row(by_channel, o, quad, clip, row_weights, values, sums, o < n_bins)
        for o in range(n_bins + n_orients):
            for x in range(wb):
                out[o, y, x] = values[o, x]
        for k in range(4):
            for x in range(wb):
                out[texture_first + k, y, x] = sums[k, x] * row_weights[x]


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _fhog_batch_into(images, cell, n_orients, clip, bins, sample_weights, out):
    """`_fhog_into` of each image into `out` (N, H//cell, W//cell, C), channel-last, all of
    image i's values times `sample_weights[i]` (channels `_fhog_into` leaves stay zero)."""
    count, rows, cols, channels = out.shape
    weights = np.empty((rows, cols), np.float32)
    channel_first = np.zeros((channels, rows, cols), np.float32)
    for i in range(count):
        weights[:] = sample_weights[i]
        _fhog_into(images[i], cell, n_orients, clip, bins, weights, channel_first)
        target = out[i]
        for y in range(rows):
            for x in range(cols):
                for c in range(channels):
                    target[y, x, c] = channel_first[c, y, x]
