"""fHOG in numba kernels (the fast backend): the steps of the reference `autotrack.tracker.fhog`
(Piotr Dollar's toolbox semantics, which the module's docstring lists) in a few passes over the
pixels, the scale samples side by side. Agrees with the reference to ~1e-7 on real patches
(tests/test_backend.py); float32 throughout, no fastmath.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

from autotrack.errors import InputError
from autotrack.tracker.backend.gradients import (
    gradient_histogram,
    histogram_extent,
    planar_float32,
    strongest_gradients,
)
from autotrack.tracker.fhog import (
    ACOS_OFFSET,
    TEXTURE_WEIGHT,
    TOOLBOX_PI,
    acos_table,
    check_settings,
    checked_images,
    fhog_channels,
)

FHOG_TRUNCATION_CHANNELS = 1
"""The toolbox appends one all-zero truncation channel; trackers drop it."""

_HALF = np.float32(0.5)
_ONE = np.float32(1.0)


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _orientation_bin_table(table, n_bins, bins):
    """bins[i] and bins[len(table) + i]: gradHist's bin of the angle table[i], and of
    table[i] + pi (a negative y-gradient), in its float32 arithmetic."""
    bins_per_radian = np.float32(n_bins) / (np.float32(2.0) * TOOLBOX_PI)
    for i in range(bins.size):
        angle = table[i % table.size] + (TOOLBOX_PI if i >= table.size else np.float32(0.0))
        bin_index = int(angle * bins_per_radian + _HALF)
        bins[i] = 0 if bin_index >= n_bins else bin_index


@lru_cache(maxsize=8)
def orientation_bins(n_orients: int) -> np.ndarray:
    """The contrast-sensitive bin (of 2 n_orients) of each acos-table entry, read-only: entry
    i for a non-negative y-gradient, len(acos_table()) + i for a negative one. The per-pixel
    angle arithmetic done once per entry: the kernel reads a byte instead."""
    bins = np.empty(4 * ACOS_OFFSET, np.uint8 if n_orients <= 127 else np.int64)
    _orientation_bin_table(acos_table(), 2 * n_orients, bins)
    bins.flags.writeable = False
    return bins


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _block_normalisers(hist, n_orients, first, wb, cell):
    """hogNormMatrix of one image's cells, columns first..first+wb of a histogram's insensitive
    bins (`hist[2n:3n]`, read in place: a C-contiguous array's rows vectorise, a view's
    would not): 1/sqrt(2x2 block energy + eps) on an (hb+1, wb+1) grid, border copied.

    Entry [i+1, j+1] belongs to the block whose top-left cell is (i, j). The border is filled in
    the C code's order, which matters only when hb or wb is 1 (then raw energies leak through,
    as in the toolbox).
    """
    hb = hist.shape[1]
    norm = np.zeros((hb + 1, wb + 1), np.float32)
    for o in range(2 * n_orients, 3 * n_orients):
        for y in range(hb):
            for x in range(wb):  # plain indexing: a view per row would cost reference counts
                value = hist[o, y, first + x]
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


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _cell_factors(norm, factors, first):
    """The four block normalisers of each cell of one image (`_block_normalisers`' grid) as
    cell-aligned planes, into columns first.. of `factors` (4, hb, columns): hogChannels'
    GETT(0), (1), (hb1), (hb1+1), the blocks at (y+1, x+1), (y, x+1), (y+1, x) and (y, x)."""
    hb, wb = norm.shape[0] - 1, norm.shape[1] - 1
    for y in range(hb):
        for x in range(wb):
            factors[0, y, first + x] = norm[y + 1, x + 1]
            factors[1, y, first + x] = norm[y, x + 1]
            factors[2, y, first + x] = norm[y + 1, x]
            factors[3, y, first + x] = norm[y, x]


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _normalised_channels(by_channel, n_orients, factors, clip, weights, out):
    """hogChannels on the 2n sensitive and n insensitive bins of `by_channel` (3n, hb, cols),
    each cell's four normalisers in `factors` (4, hb, cols): the mean of a cell's value under
    them, each clipped, times `weights[y, x]`, into `out[o]`, and the 4 texture channels (the
    clipped sensitive values times the texture weight, summed over the orientations in the
    toolbox's order) into `out[3n:3n+4]`. Whole cell rows at a time, one channel after
    another, with plain indexing (no views: a view per row costs reference counting); the
    columns may be several images' cells side by side."""
    n_bins = 2 * n_orients
    hb, cols = by_channel.shape[1], by_channel.shape[2]
    texture_first = 3 * n_orients
    sums = np.empty((4, cols), np.float32)
    for y in range(hb):
        for k in range(4):
            for x in range(cols):
                sums[k, x] = 0.0
        for o in range(n_bins + n_orients):
            texture = o < n_bins
            for x in range(cols):
                r = by_channel[o, y, x]
                t0 = min(r * factors[0, y, x], clip)
                t1 = min(r * factors[1, y, x], clip)
                t2 = min(r * factors[2, y, x], clip)
                t3 = min(r * factors[3, y, x], clip)
                out[o, y, x] = (t0 * _HALF + t1 * _HALF + t2 * _HALF + t3 * _HALF) * weights[y, x]
                if texture:
                    sums[0, x] += t0 * TEXTURE_WEIGHT
                    sums[1, x] += t1 * TEXTURE_WEIGHT
                    sums[2, x] += t2 * TEXTURE_WEIGHT
                    sums[3, x] += t3 * TEXTURE_WEIGHT
        for k in range(4):
            for x in range(cols):
                out[texture_first + k, y, x] = sums[k, x] * weights[y, x]


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _insensitive_sums(by_channel, n_orients):
    """The n contrast-insensitive bins, the sums of opposite sensitive ones, into
    `by_channel[2n:3n]`."""
    for o in range(n_orients):
        for y in range(by_channel.shape[1]):
            for x in range(by_channel.shape[2]):
                by_channel[2 * n_orients + o, y, x] = (
                    by_channel[o, y, x] + by_channel[o + n_orients, y, x]
                )


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _cell_factor_planes(hist, n_orients, cell, sample_cells):
    """The contrast-insensitive bins of a histogram of images side by side (`gradient_histogram`,
    (3n, rows, N cols), `sample_cells` columns each), written into it, and the four block
    normalisers of every cell as (4, rows, N cols) planes (`_cell_factors`), each image's
    block normalisers its own."""
    rows, columns = hist.shape[1], hist.shape[2]
    _insensitive_sums(hist, n_orients)
    factors = np.empty((4, rows, columns), np.float32)
    for first in range(0, columns, sample_cells):
        norm = _block_normalisers(hist, n_orients, first, sample_cells, cell)
        _cell_factors(norm, factors, first)
    return factors


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _channel_last(channel_first, sample_weights, out):
    """out[i, y, x, c] = channel_first[c, y, i cols + x] * sample_weights[i]: images side by
    side, channel-first, as a channel-last stack, each image times its weight."""
    count, rows, cols = out.shape[0], out.shape[1], out.shape[2]
    channels = channel_first.shape[0]
    for i in range(count):
        target, weight = out[i], sample_weights[i]
        for y in range(rows):
            for x in range(cols):
                for c in range(channels):
                    target[y, x, c] = channel_first[c, y, i * cols + x] * weight


def _normalised_cells(hist, n_orients, cell, sample_cells, clip, weights, out) -> None:
    """The cells of a histogram (`_histogram`, the insensitive bins still zero) normalised, each
    cell's values times `weights[y, x]`, into `out` (>= 3n+4, rows, cols), channel-first
    (channels past 3n+4, the toolbox's zero channel, are left as they are): hogChannels.

    A float32 product rounds once wherever it is taken, so `out` holds exactly what the
    unweighted features times the weights would give (weights of one give the features).
    """
    factors = _cell_factor_planes(hist, n_orients, cell, sample_cells)
    _normalised_channels(hist, n_orients, factors, np.float32(clip), weights, out)


def _histogram(pixels: np.ndarray, cell: int, n_orients: int, cells: tuple[int, int]):
    """The (3n, rows, N cols) histogram of the (N, H, W, C) images side by side, each image's
    `cells` (rows, cols) of cells its own: `planar_float32`, `strongest_gradients` and
    `gradient_histogram`, three kernels called one after the other (each compiled on its own:
    a kernel that calls another recompiles the callee's code into its own)."""
    count, _, width = pixels.shape[:3]
    planes = planar_float32(pixels)
    hist = np.zeros((3 * n_orients, cells[0], count * cells[1]), np.float32)
    rows, cols = histogram_extent(hist.shape, cell, width, cells[1])
    gradients = strongest_gradients(planes, rows, cols, width)
    bins = orientation_bins(n_orients)
    gradient_histogram(gradients, cell, 2 * n_orients, bins, hist, width, cells[1])
    return hist


def fhog(
    image: np.ndarray, cell_size: int = 4, n_orients: int = 9, clip: float = 0.2
) -> np.ndarray:
    """Piotr Dollar's `fhog(single(image), cell_size, n_orients, clip)`.

    `image` is H x W or H x W x C of any real dtype, used as float32 on its own scale (0..255 for
    8-bit images; do not divide by 255). Returns float32 (H//cell, W//cell, 3n+5) in the
    toolbox's channel order: 2n contrast-sensitive orientations, n contrast-insensitive ones, 4
    texture (block energy) channels and one all-zero channel that callers drop.
    """
    check_settings(cell_size, n_orients, clip)
    pixels = checked_images(image, 2)
    height, width = pixels.shape[:2]
    out = np.zeros(
        (height // cell_size, width // cell_size, fhog_channels(n_orients)), dtype=np.float32
    )
    weights = np.ones(out.shape[:2], np.float32)
    _fhog_into(pixels, int(cell_size), int(n_orients), clip, weights, out.transpose(2, 0, 1))
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
    check_settings(cell_size, n_orients, clip)
    pixels = checked_images(image, 2)
    cells = (pixels.shape[0] // cell_size, pixels.shape[1] // cell_size)
    shape = (fhog_channels(n_orients) - 1, *cells)
    if weights.shape != cells or out.shape != shape:
        raise InputError(
            f"fhog of a {pixels.shape[0]} x {pixels.shape[1]} image at cell {cell_size} needs "
            f"weights {cells} and out {shape}, got {weights.shape} and {out.shape}"
        )
    _fhog_into(pixels, int(cell_size), int(n_orients), clip, weights, out)


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
    check_settings(cell_size, n_orients, clip)
    stack = np.asarray(images)
    if stack.ndim not in (3, 4):
        raise InputError(
            f"fhog_batch needs a stack of shape N x H x W or N x H x W x C, got {stack.shape}"
        )
    pixels = checked_images(stack, 3)
    count, height, width = pixels.shape[:3]
    channels = fhog_channels(n_orients)
    if sample_weights is None:
        weights = np.ones(count, np.float32)
    else:
        weights = np.ascontiguousarray(sample_weights, dtype=np.float32)
        if weights.shape != (count,):
            raise InputError(f"fhog_batch needs {count} sample weights, got {weights.shape}")
        channels -= FHOG_TRUNCATION_CHANNELS
    out = np.zeros((count, height // cell_size, width // cell_size, channels), np.float32)
    if out.size:  # normalised side by side, then each image's cells times its weight
        rows, cols = out.shape[1:3]
        hist = _histogram(pixels, int(cell_size), int(n_orients), (rows, cols))
        channel_first = np.empty((fhog_channels(n_orients) - 1, rows, count * cols), np.float32)
        ones = np.ones((rows, count * cols), np.float32)  # (v * 1) * w is v * w, bit for bit
        _normalised_cells(hist, int(n_orients), int(cell_size), cols, clip, ones, channel_first)
        _channel_last(channel_first, weights, out)
    return out


def _fhog_into(
    pixels: np.ndarray,
    cell: int,
    n_orients: int,
    clip: float,
    weights: np.ndarray,
    out: np.ndarray,
) -> None:
    """fhog of one (H, W, C) image times `weights` into `out` (>= 3n+4, H//cell, W//cell),
    channel-first, any strides (`_normalised_cells`)."""
    if out.shape[1] and out.shape[2]:
        hist = _histogram(pixels[None], cell, n_orients, out.shape[1:])
        _normalised_cells(hist, n_orients, cell, out.shape[2], clip, weights, out)
