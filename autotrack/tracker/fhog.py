"""Felzenszwalb HOG as computed by Piotr Dollar's toolbox `fhog(I, binSize, nOrients, clip)`.

A port of the semantics of the toolbox's gradientMex.cpp (v3.30: `gradMag`, `gradHist` with
softBin = -1, `hogNormMatrix`, `hogChannels`, `fhog`), which the AutoTrack release calls as
`fhog(single(patch), 4, 9)`. dlib's fHOG (`pyfhog`) differs and must not be substituted.

Per pixel (only the first (H//cell)*cell rows and (W//cell)*cell columns are used):
1. Centred differences (one-sided, factor 1, at the image border); with several channels the one
   with the largest squared magnitude wins (a later channel only if strictly larger).
2. The orientation in [0, 2 pi) goes to one of 2 * n_orients bins without orientation
   interpolation; the magnitude / cell^2 is spread bilinearly over the 4 nearest cells, and the
   border cells are scaled by 8/7 (they miss 1/8 of the interior weight).
3. Contrast-insensitive bins are the sums of opposite sensitive bins; each cell is normalised by
   its four 2 x 2 blocks' energies, clipped at `clip`, and summed into 2n + n orientation
   channels and 4 texture channels; a last, all-zero channel completes the toolbox's 3n + 5.

Deliberate differences: the toolbox takes the magnitude and the unit gradient from SSE
`rcp`/`rsqrt` approximations (about 12 correct bits, hardware dependent); here they are exact
float32. Everything else (acos lookup table, float32 bin arithmetic, block energies and the
order the normaliser border is filled in) follows the C code, so orientation bins agree except
where the approximation itself moves a gradient across a bin edge.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

from autotrack.errors import InputError
from autotrack.tracker.gradients import planar_float32, row_gradients, strongest_gradients

FHOG_TRUNCATION_CHANNELS = 1
"""The toolbox appends one all-zero truncation channel; trackers drop it."""

_PI = np.float32(3.14159265)  # the toolbox's PI (a float literal)
_ACOS_STEPS = 10000  # acosTable: a[i] ~= acos(i / 10000)
_ACOS_PAD = 10
_ACOS_OFFSET = _ACOS_STEPS + _ACOS_PAD
_TEXTURE_WEIGHT = np.float32(0.2357)  # ~ 1 / sqrt(18), hogChannels' r
_HALF = np.float32(0.5)
_ONE = np.float32(1.0)
_MINUS_ONE = np.float32(-1.0)
_BORDER_GAIN = np.float32(8.0) / np.float32(7.0)
_ZERO_GRADIENT_INVERSE = np.float32(1e10)  # min(rsqrt(0), 1e10) in gradMag


def fhog_channels(n_orients: int = 9) -> int:
    """Channels the toolbox returns: 2n sensitive + n insensitive + 4 texture + 1 zero."""
    return 3 * n_orients + 5


@lru_cache(maxsize=1)
def acos_table() -> np.ndarray:
    """The toolbox's acosTable(): float32 acos(i / 10000) for i in [-10010, 10010), read-only.

    Entries below -10000 are pi, above 9999 zero, and values above pi - 1e-6 are clamped to
    pi - 1e-6 (so that adding pi for negative y-gradients stays below 2 pi). Index with
    `int(x * 10000) + 10010`.
    """
    table = np.empty(2 * _ACOS_OFFSET, dtype=np.float32)
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
    """bins[i] and bins[len(table) + i]: gradHist's bin of the angle table[i], and of
    table[i] + pi (a negative y-gradient), in its float32 arithmetic."""
    bins_per_radian = np.float32(n_bins) / (np.float32(2.0) * _PI)
    for i in range(bins.size):
        angle = table[i % table.size] + (_PI if i >= table.size else np.float32(0.0))
        bin_index = int(angle * bins_per_radian + _HALF)
        bins[i] = 0 if bin_index >= n_bins else bin_index


@lru_cache(maxsize=8)
def orientation_bins(n_orients: int) -> np.ndarray:
    """The contrast-sensitive bin (of 2 n_orients) of each acos-table entry, read-only: entry
    i for a non-negative y-gradient, len(acos_table()) + i for a negative one. The per-pixel
    angle arithmetic done once per entry: the kernel reads a byte instead."""
    bins = np.empty(4 * _ACOS_OFFSET, np.uint8 if n_orients <= 127 else np.int64)
    _orientation_bin_table(acos_table(), 2 * n_orients, bins)
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


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _gradient_histogram(planes, cell, n_bins, bins, hist, sample_width, sample_cells):
    """gradMag (full orientation) + gradHist(softBin=-1): bilinear in space, hard in angle.

    `planes` is float32 (C, H, W), `bins` `orientation_bins(n_bins // 2)`, `hist` C-contiguous
    (>= n_bins, hb, wb), channel-major: a pixel's right cell is the next float, not n_bins on.
    `planes` may hold several images side by side, `sample_width` columns each, whose
    histograms `hist` then holds side by side, `sample_cells` columns each (one image: its
    width and wb): each image's gradients, cells and borders are its own, and every cell sums
    its pixels in the same order as for the image alone, so the same bits; the rows of all
    the images run as one long row.
    The colour channel is chosen for the whole image first (`strongest_gradients`), then row by
    row in small vectorisable passes, branch-free where the data decide (random gradient
    signs would defeat branch prediction); the scatter indexes the flat histogram with unsigned
    indices (no negative-index wraparound code per access).
    """
    hb, wb = hist.shape[1], hist.shape[2]
    rows = hb * cell
    inv_cell2 = _ONE / np.float32(cell) / np.float32(cell)
    unit = np.float32(_ACOS_STEPS)
    zero = np.float32(0.0)
    samples = wb // sample_cells
    used = sample_cells * cell  # an image's columns that fill whole cells
    cols = (samples - 1) * sample_width + used
    x_first, x_frac = _bin_coordinates(used, cell)
    y_first, y_frac = _bin_coordinates(rows, cell)
    channels = planes.shape[0]
    grey_row = np.empty((3, cols), np.float32)  # a grey row's gx, gy and squared
    row_gx, row_gy, row_squared = grey_row[0], grey_row[1], grey_row[2]
    image_gx, image_gy, image_squared = strongest_gradients(
        planes, rows if channels > 1 else 0, cols, sample_width
    )
    table_index = np.empty(cols, np.uint32)
    weight = np.empty(cols, np.float32)
    orient = np.empty(cols, np.int64)
    flat = hist.reshape(-1)
    plane = hb * wb
    for y in range(rows):
        if channels == 1:  # no choice to make: the row's gradients, kept in cache
            gx, gy, squared = row_gx, row_gy, row_squared
            row_gradients(planes[0], y, gx, gy, sample_width)
            for x in range(cols):
                squared[x] = gx[x] * gx[x] + gy[x] * gy[x]
        else:
            gx, gy, squared = image_gx[y], image_gy[y], image_squared[y]
        for x in range(cols):
            magnitude = np.float32(math.sqrt(squared[x]))
            inverse = min(_ONE / magnitude, _ZERO_GRADIENT_INVERSE)
            negative = gy[x] < zero
            # acos of the unit x-gradient, sign-flipped for negative y, via the toolbox's table;
            # `bins` adds pi for negative y (its second half), mapping the angle to [0, 2 pi),
            # and rounds it to a bin. (atan2 would differ at bin edges only.)
            sign = _MINUS_ONE if negative else _ONE
            index = np.int32(gx[x] * inverse * unit * sign) + _ACOS_OFFSET
            table_index[x] = index + (2 * _ACOS_OFFSET if negative else 0)
            weight[x] = magnitude * inv_cell2
        for x in range(cols):
            orient[x] = np.int64(bins[table_index[x]]) * plane
        y0 = y_first[y]
        yd = y_frac[y]
        top = y0 * wb  # flat index of hist[0, y0, 0]
        if samples == 1:
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


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _block_normalisers(insensitive, cell):
    """hogNormMatrix: 1/sqrt(2x2 block energy + eps) on an (hb+1, wb+1) grid, border copied.

    Entry [i+1, j+1] belongs to the block whose top-left cell is (i, j). The border is filled in
    the C code's order, which matters only when hb or wb is 1 (then raw energies leak through,
    as in the toolbox).
    """
    n_orients, hb, wb = insensitive.shape
    norm = np.zeros((hb + 1, wb + 1), np.float32)
    for o in range(n_orients):
        for y in range(hb):
            for x in range(wb):
                value = insensitive[o, y, x]
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
def _normalised_row(by_channel, o, norm, y, clip, weights, out, sums, texture):
    """Cell row y of orientation channel o (hogChannels) of `by_channel` (channels, hb, wb): the
    mean of each cell's value under its four block normalisers, each clipped, times `weights`,
    into `out[o, y]`; with `texture`, the clipped values times the texture weight are added to
    `sums` (4, cols). Inlined, with plain indexing and no array views: a call or a view per row
    costs reference counting, which on the scale filter's 6 x 4-cell samples was most of the
    time."""
    for x in range(by_channel.shape[2]):
        r = by_channel[o, y, x]
        # The four blocks containing cell (y, x): hogChannels' GETT(0), (1), (hb1), (hb1+1).
        t0 = min(r * norm[y + 1, x + 1], clip)
        t1 = min(r * norm[y, x + 1], clip)
        t2 = min(r * norm[y + 1, x], clip)
        t3 = min(r * norm[y, x], clip)
        out[o, y, x] = (t0 * _HALF + t1 * _HALF + t2 * _HALF + t3 * _HALF) * weights[y, x]
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
    unweighted features times the weights would give (weights of one give the features).
    """
    hb, wb = out.shape[1], out.shape[2]
    if hb == 0 or wb == 0:
        return
    # The 2n sensitive bins then the n insensitive ones, channel-major (one plane per bin).
    bins_by_channel = np.zeros((3 * n_orients, hb, wb), np.float32)
    planes = planar_float32(image)
    _gradient_histogram(planes, cell, 2 * n_orients, bins, bins_by_channel, planes.shape[2], wb)
    _normalised_cells(bins_by_channel, cell, n_orients, clip, weights, out)


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _normalised_cells(bins_by_channel, cell, n_orients, clip, weights, out):
    """hogChannels on the 2n sensitive bins of `bins_by_channel` (3n, hb, wb; the n insensitive
    ones are written here), times `weights`, into `out` as `_fhog_into` describes. The
    normalisation runs along whole cell rows, one channel at a time, each texture sum still
    taken over the orientations in the toolbox's order."""
    n_bins = 2 * n_orients
    hb, wb = out.shape[1], out.shape[2]
    for o in range(n_orients):
        for y in range(hb):
            for x in range(wb):
                bins_by_channel[n_bins + o, y, x] = (
                    bins_by_channel[o, y, x] + bins_by_channel[o + n_orients, y, x]
                )
    norm = _block_normalisers(bins_by_channel[n_bins:], cell)
    texture_first = 3 * n_orients
    sums = np.empty((4, wb), np.float32)
    for y in range(hb):
        for k in range(4):
            for x in range(wb):
                sums[k, x] = 0.0
        for o in range(n_bins + n_orients):
            _normalised_row(bins_by_channel, o, norm, y, clip, weights, out, sums, o < n_bins)
        for k in range(4):
            for x in range(wb):
                out[texture_first + k, y, x] = sums[k, x] * weights[y, x]


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _fhog_batch_into(images, cell, n_orients, clip, bins, sample_weights, out):
    """`_fhog_into` of each image into `out` (N, H//cell, W//cell, C), channel-last, all of
    image i's values times `sample_weights[i]` (channels `_fhog_into` leaves stay zero).

    The images' histograms are taken side by side in one pass (`_gradient_histogram`), whose
    rows then run N times as long: the scale filter's 22 x 22 samples gave rows of 20 pixels."""
    count, rows, cols, channels = out.shape
    if count == 0 or rows == 0 or cols == 0:
        out[:] = 0.0
        return
    height, width, colours = images.shape[1], images.shape[2], images.shape[3]
    planes = np.empty((colours, height, count * width), np.float32)
    for i in range(count):
        sample = planar_float32(images[i])
        for c in range(colours):
            for y in range(height):
                for x in range(width):
                    planes[c, y, i * width + x] = sample[c, y, x]
    side_by_side = np.zeros((3 * n_orients, rows, count * cols), np.float32)
    _gradient_histogram(planes, cell, 2 * n_orients, bins, side_by_side, width, cols)
    weights = np.empty((rows, cols), np.float32)
    channel_first = np.zeros((channels, rows, cols), np.float32)
    for i in range(count):
        weights[:] = sample_weights[i]
        own = np.ascontiguousarray(side_by_side[:, :, i * cols : (i + 1) * cols])
        _normalised_cells(own, cell, n_orients, clip, weights, channel_first)
        target = out[i]
        for y in range(rows):
            for x in range(cols):
                for c in range(channels):
                    target[y, x, c] = channel_first[c, y, x]


def _as_kernel_input(images: np.ndarray, image_axes: int) -> np.ndarray:
    """C-contiguous uint8 or float32 with an explicit channel axis (the kernels' two dtypes)."""
    array = np.asarray(images)
    if array.dtype != np.uint8:
        if not (np.issubdtype(array.dtype, np.number) or array.dtype == np.bool_):
            raise InputError(f"fhog needs a numeric image, got dtype {array.dtype}")
        if np.iscomplexobj(array):
            raise InputError("fhog needs a real-valued image, got a complex array")
        array = array.astype(np.float32, copy=False)
    if array.ndim == image_axes:
        array = array[..., None]
    if array.ndim != image_axes + 1 or array.shape[-1] < 1:
        raise InputError(
            f"fhog needs images of shape H x W or H x W x C, got array shape {np.shape(images)}"
        )
    height, width = array.shape[-3], array.shape[-2]
    if height < 2 or width < 2:
        raise InputError(f"fhog needs an image of at least 2 x 2 pixels, got {height} x {width}")
    return np.ascontiguousarray(array)


def _check_settings(cell_size: int, n_orients: int, clip: float) -> None:
    if int(cell_size) != cell_size or cell_size < 1:
        raise InputError(f"fhog cell_size must be a positive integer, got {cell_size}")
    if int(n_orients) != n_orients or n_orients < 1:
        raise InputError(f"fhog n_orients must be a positive integer, got {n_orients}")
    if not (math.isfinite(clip) and clip > 0):
        raise InputError(f"fhog clip must be a positive number, got {clip}")


def fhog(
    image: np.ndarray, cell_size: int = 4, n_orients: int = 9, clip: float = 0.2
) -> np.ndarray:
    """Piotr Dollar's `fhog(single(image), cell_size, n_orients, clip)`.

    `image` is H x W or H x W x C of any real dtype, used as float32 on its own scale (0..255 for
    8-bit images; do not divide by 255). Returns float32 (H//cell, W//cell, 3n+5) in the
    toolbox's channel order: 2n contrast-sensitive orientations, n contrast-insensitive ones, 4
    texture (block energy) channels and one all-zero channel that callers drop.
    """
    _check_settings(cell_size, n_orients, clip)
    pixels = _as_kernel_input(image, 2)
    height, width = pixels.shape[:2]
    out = np.zeros(
        (height // cell_size, width // cell_size, fhog_channels(n_orients)), dtype=np.float32
    )
    weights = np.ones(out.shape[:2], np.float32)
    bins = orientation_bins(int(n_orients))
    _fhog_into(
        pixels,
        int(cell_size),
        int(n_orients),
        np.float32(clip),
        bins,
        weights,
        out.transpose(2, 0, 1),
    )
    return out


def fhog_weighted_into(
    image: np.ndarray,
    weights: np.ndarray,
    out: np.ndarray,
    cell_size: int = 4,
    n_orients: int = 9,
    clip: float = 0.2,
) -> None:
    """`fhog(image, ...)` times float32 `weights` (H//cell, W//cell), written channel-first into
    `out` (3n+4, H//cell, W//cell), any strides, without the zero channel: a slice of a
    transform's input buffer takes the windowed features in the same pass, exactly the values
    `fhog(image)[..., :3n+4].transpose(2, 0, 1) * weights` has."""
    _check_settings(cell_size, n_orients, clip)
    pixels = _as_kernel_input(image, 2)
    cells = (pixels.shape[0] // cell_size, pixels.shape[1] // cell_size)
    shape = (fhog_channels(n_orients) - 1, *cells)
    if weights.shape != cells or out.shape != shape:
        raise InputError(
            f"fhog of a {pixels.shape[0]} x {pixels.shape[1]} image at cell {cell_size} needs "
            f"weights {cells} and out {shape}, got {weights.shape} and {out.shape}"
        )
    bins = orientation_bins(int(n_orients))
    _fhog_into(pixels, int(cell_size), int(n_orients), np.float32(clip), bins, weights, out)


def fhog_batch(
    images: np.ndarray,
    cell_size: int = 4,
    n_orients: int = 9,
    clip: float = 0.2,
    sample_weights: np.ndarray | None = None,
) -> np.ndarray:
    """`fhog` of each image of an (N, H, W) or (N, H, W, C) stack -> (N, H//cell, W//cell, 3n+5).

    With `sample_weights` (N,) the result is (N, H//cell, W//cell, 3n+4), without the zero
    channel, and image i's values are times `sample_weights[i]` (float32, rounded once: exactly
    the unweighted features times the weight).
    """
    _check_settings(cell_size, n_orients, clip)
    stack = np.asarray(images)
    if stack.ndim not in (3, 4):
        raise InputError(
            f"fhog_batch needs a stack of shape N x H x W or N x H x W x C, got {stack.shape}"
        )
    pixels = _as_kernel_input(stack, 3)
    count, height, width = pixels.shape[:3]
    channels = fhog_channels(n_orients)
    if sample_weights is None:
        weights = np.ones(count, np.float32)
    else:
        weights = np.ascontiguousarray(sample_weights, dtype=np.float32)
        if weights.shape != (count,):
            raise InputError(f"fhog_batch needs {count} sample weights, got {weights.shape}")
        channels -= FHOG_TRUNCATION_CHANNELS
    out = np.empty((count, height // cell_size, width // cell_size, channels), np.float32)
    bins = orientation_bins(int(n_orients))
    _fhog_batch_into(pixels, int(cell_size), int(n_orients), np.float32(clip), bins, weights, out)
    return out
