"""The feature stack of `features` in compiled kernels (the fast backend): the cell means, the
colour lookup and fHOG (`fast_fhog`) each in one pass, the cosine window taken in the pass that
computes a map, written straight into the buffer a transform reads. Checked against
`features.feature_maps` / `features.scale_features` on real patches (tests/test_backend.py)."""

from __future__ import annotations

import numpy as np
from numba import njit

from autotrack.errors import InputError
from autotrack.params import TrackerParams
from autotrack.tracker.backend.fast_fhog import fhog_batch, fhog_weighted_into
from autotrack.tracker.features import (
    FHOG_CHANNELS,
    GREY_CHANNELS,
    RGB2GRAY_WEIGHTS,
    SCALE_FEATURE_CELL,
    checked_lookup,
    feature_dim,
    feature_patch,
    lab11_table,
)


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _cell_means(values, cell, out):
    """Block means of (H, W, K) values into (H//cell, W//cell, K), accumulated in float32."""
    rows, cols, depth = out.shape
    width = cols * cell * depth
    band = np.empty(width, np.float32)
    scale = np.float32(1.0) / np.float32(cell * cell)
    for row in range(rows):
        first = values[row * cell].reshape(-1)[:width]
        for i in range(width):
            band[i] = np.float32(first[i])
        for y in range(row * cell + 1, (row + 1) * cell):
            line = values[y].reshape(-1)[:width]
            for i in range(width):  # whole rows at a time: contiguous, vectorised
                band[i] += np.float32(line[i])
        for col in range(cols):
            for k in range(depth):
                total = np.float32(0.0)
                for dx in range(cell):
                    total += band[(col * cell + dx) * depth + k]
                out[row, col, k] = total * scale


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _band_indices(patch, row, cell, index):
    """Table rows R//8 + 32 (G//8) + 1024 (B//8) of the pixels of cell row `row`, (cell, width)."""
    width = index.shape[1]
    for dy in range(cell):
        line = patch[row * cell + dy]
        target = index[dy]
        for x in range(width):
            target[x] = (
                (np.int64(line[x, 0]) >> 3)
                + ((np.int64(line[x, 1]) >> 3) << 5)
                + ((np.int64(line[x, 2]) >> 3) << 10)
            )


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _lookup_cell_average(patch, table, cell, weights, out):
    """Cell means of table[R//8 + 32 (G//8) + 1024 (B//8)] over an RGB uint8 patch, each cell's
    mean times `weights[row, col]` (rounded once after the mean), into `out` of any strides.

    Each cell's sum runs over its pixels row by row, left to right, in float32 from zero; with
    the tables' 10 channels the ten sums stay in registers (no array views, no stores between
    the additions)."""
    rows, cols, depth = out.shape
    index = np.empty((cell, cols * cell), np.int64)
    scale = np.float32(1.0) / np.float32(cell * cell)
    zero = np.float32(0.0)
    for row in range(rows):
        _band_indices(patch, row, cell, index)
        for col in range(cols):
            weight = weights[row, col]
            first = col * cell
            if depth == 10:
                s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = s8 = s9 = zero
                for dy in range(cell):
                    for dx in range(first, first + cell):
                        i = index[dy, dx]
                        s0 += table[i, 0]
                        s1 += table[i, 1]
                        s2 += table[i, 2]
                        s3 += table[i, 3]
                        s4 += table[i, 4]
                        s5 += table[i, 5]
                        s6 += table[i, 6]
                        s7 += table[i, 7]
                        s8 += table[i, 8]
                        s9 += table[i, 9]
                sums = (s0, s1, s2, s3, s4, s5, s6, s7, s8, s9)
                for k in range(10):
                    out[row, col, k] = (sums[k] * scale) * weight
            else:
                for k in range(depth):
                    total = zero
                    for dy in range(cell):
                        for dx in range(first, first + cell):
                            total += table[index[dy, dx], k]
                    out[row, col, k] = (total * scale) * weight


def colour_table_feature(patch_rgb_uint8: np.ndarray, table: np.ndarray, cell: int) -> np.ndarray:
    """`features.colour_table_feature` on the compiled lookup -> (H//c, W//c, table columns)."""
    rgb, lookup = checked_lookup(patch_rgb_uint8, table)
    out = np.empty((rgb.shape[0] // cell, rgb.shape[1] // cell, lookup.shape[1]), np.float32)
    _lookup_cell_average(rgb, lookup, cell, np.ones(out.shape[:2], np.float32), out)
    return out


def grey_feature(patch: np.ndarray, cell: int) -> np.ndarray:
    """`features.grey_feature` on the compiled cell means."""
    values = patch[:, :, None] if patch.ndim == 2 else patch
    height, width, depth = values.shape
    means = np.empty((height // cell, width // cell, depth), np.float32)
    _cell_means(np.ascontiguousarray(values), cell, means)
    if depth == 3:
        grey = means @ (RGB2GRAY_WEIGHTS / 255.0).astype(np.float32)
        return (grey - np.float32(0.5))[:, :, None]
    return means / np.float32(255.0) - np.float32(0.5)


def feature_maps(
    patch: np.ndarray,
    params: TrackerParams,
    colour_table: np.ndarray | None,
    window: np.ndarray | None = None,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """The release's feature stack of one patch, channel-first: float32 (K, H//c, W//c).

    `patch` is uint8 RGB (H x W x 3) or grey (H x W); a grey patch gets no colour channels.
    Order: grey (1), fHOG (31), colour (10), each when enabled in `params`; colour_feature
    'table' uses `colour_table` (a 32768-row table, see `load_colour_table`). With a float32
    `window` (H//c, W//c) every map is times the window, taken in the pass that computes it (a
    float32 product rounds once wherever it is taken, so these are exactly the maps times the
    window). Written into `out` (e.g. a transform's input buffer) when given; returned.
    """
    array = feature_patch(patch, params, colour_table)
    cell = int(params.cell_size)
    shape = (feature_dim(params, array.ndim == 3), array.shape[0] // cell, array.shape[1] // cell)
    if window is None:
        window = np.ones(shape[1:], np.float32)
    if window.shape != shape[1:] or window.dtype != np.float32:
        raise InputError(
            f"the window must be float32 {shape[1:]}, got {window.dtype} {window.shape}"
        )
    if out is None:
        out = np.empty(shape, np.float32)
    elif out.shape != shape or out.dtype != np.float32:
        raise InputError(f"feature maps need a float32 {shape} buffer, got {out.dtype} {out.shape}")
    channel = 0
    if params.use_grey:
        np.multiply(grey_feature(array, cell)[:, :, 0], window, out=out[0])
        channel += GREY_CHANNELS
    if params.use_fhog:
        fhog_weighted_into(array, window, out[channel : channel + FHOG_CHANNELS], cell)
        channel += FHOG_CHANNELS
    if array.ndim == 3 and params.colour_feature != "none":
        table = colour_table if params.colour_feature == "table" else lab11_table()
        rgb, lookup = checked_lookup(array, table)
        _lookup_cell_average(rgb, lookup, cell, window, out[channel:].transpose(1, 2, 0))
    return out


def scale_features(patches: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Scale-filter samples: fHOG (cell 4, 31 channels) of each patch, flattened -> (N, D).

    `patches` is (N, h, w) or (N, h, w, 3). Each patch's (h//4, w//4, 31) block is flattened in
    C order (the release uses MATLAB's column-major order; the scale filter only needs one fixed
    order). With float32 `weights` (N,) sample i is times weights[i] (the scale window), taken in
    the pass that computes it: exactly the unweighted samples times the weights.
    """
    stack = np.asarray(patches)
    if stack.ndim not in (3, 4):
        raise InputError(
            f"scale samples must be N x h x w or N x h x w x 3, got shape {stack.shape}"
        )
    if weights is None:
        weights = np.ones(stack.shape[0], np.float32)
    hog = fhog_batch(stack, SCALE_FEATURE_CELL, sample_weights=weights)
    return hog.reshape(stack.shape[0], -1)
