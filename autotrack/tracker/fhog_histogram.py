"""fHOG's first stage, the toolbox's `gradMag` + `gradHist(softBin = -1)`: per pixel the
strongest channel's gradient, its orientation bin through the acos table, and its magnitude
spread bilinearly over the four nearest cells. See `fhog` for the whole feature.

Bit for bit the toolbox's float32 operations (as ported in round 1), computed faster:
- the orientation: the acos table's angle, plus pi for a negative y-gradient, times the bins
  per radian, rounded to a bin: a function of the table index and the sign alone, so it is
  read from `orientation_bins`, a small integer table of that same float32 arithmetic done once
  per entry, instead of a float gather and three operations per pixel;
- the histogram: every cell bin receives its float32 additions in the same order as before
  (pixel by pixel, row-major); the products (bilinear weight x magnitude) are taken in
  vectorised passes over the row, and the scatter runs over the row's interior without the
  per-pixel edge tests, the edge pixels (no left or no right cell) handled apart.
"""

from __future__ import annotations

import math
from functools import lru_cache

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


@lru_cache(maxsize=1)
def acos_table() -> np.ndarray:
    """The toolbox's acosTable(): float32 acos(i / 10000) for i in [-10010, 10010), read-only.

    Entries below -10000 are pi, above 9999 zero, and values above pi - 1e-6 are clamped to
    pi - 1e-6 (so that adding pi for negative y-gradients stays below 2 pi). Index with
    `int(x * 10000) + 10010`.
    """
    table = np.empty(_ACOS_ENTRIES, dtype=np.float32)
    steps = np.arange(-_ACOS_STEPS, _ACOS_STEPS, dtype=np.float32) / np.float32(_ACOS_STEPS)
    table[:_ACOS_PAD] = _PI
    table[_ACOS_PAD : _ACOS_PAD + 2 * _ACOS_STEPS] = np.arccos(steps.astype(np.float64))
    table[_ACOS_PAD + 2 * _ACOS_STEPS :] = 0.0
    limit = _PI - np.float32(1e-6)
    head = table[: _ACOS_OFFSET + _ACOS_STEPS // 10]
    head[head > limit] = limit
    table.flags.writeable = False
    return table


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _orientation_bin_table(table, n_bins, bins):
    """bins[i] (i < len(table)) and bins[len(table) + i]: the bin of angle table[i], and of
    table[i] + pi, in gradHist's float32 arithmetic (as the per-pixel code computed it)."""
    entries = table.size
    bins_per_radian = np.float32(n_bins) / (np.float32(2.0) * _PI)
    for i in range(2 * entries):
        offset = _PI if i >= entries else np.float32(0.0)
        angle = table[i % entries] + offset
        bin_index = int(angle * bins_per_radian + _HALF)
        bins[i] = 0 if bin_index >= n_bins else bin_index


@lru_cache(maxsize=8)
def orientation_bins(n_orients: int) -> np.ndarray:
    """The sensitive orientation bin (of 2 n_orients) per acos-table index, read-only: entry
    `index` for a non-negative y-gradient, `len(acos_table()) + index` for a negative one."""
    n_bins = 2 * n_orients
    bins = np.empty(2 * _ACOS_ENTRIES, np.uint8 if n_bins <= 255 else np.int32)
    _orientation_bin_table(acos_table(), n_bins, bins)
    bins.flags.writeable = False
    return bins


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
def _interior_run(first, last_cell):
    """(lo, hi): pixels lo..hi-1 have a cell on both sides (first[x] >= 0, < last_cell);
    `first` is non-decreasing, so the pixels before lo have no left cell, those from hi no right."""
    lo = 0
    while lo < first.size and first[lo] < 0:
        lo += 1
    hi = lo
    while hi < first.size and first[hi] < last_cell:
        hi += 1
    return lo, hi


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _scatter(flat, top, bottom, step, start, stop, position, left, right, has_left, has_right):
    """hist[row, x0, o] += the row's products for pixels start..stop-1, in pixel order: the
    left cell at flat[top/bottom + position], the right one `step` (= n_bins) further;
    `bottom` < 0 when there is no cell row below."""
    for x in range(start, stop):
        at = position[x]
        if has_left:
            flat[top + at] += left[0, x]
            if bottom >= 0:
                flat[bottom + at] += left[1, x]
        if has_right:
            flat[top + at + step] += right[0, x]
            if bottom >= 0:
                flat[bottom + at + step] += right[1, x]


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
    lo, hi = _interior_run(x_first, wb - 1)
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
        ahead, behind = left[shares:], right[shares:]
        _scatter(flat, top, bottom, n_bins, 0, lo, position, ahead, behind, False, True)
        _scatter(flat, top, bottom, n_bins, lo, hi, position, ahead, behind, True, True)
        _scatter(flat, top, bottom, n_bins, hi, cols, position, ahead, behind, True, False)
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
