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
from autotrack.tracker.fhog_kernels import (
    _ACOS_ENTRIES,
    _ACOS_OFFSET,
    _ACOS_PAD,
    _ACOS_STEPS,
    _HALF,
    _PI,
    _fhog_batch_into,
    _fhog_into,
)

FHOG_TRUNCATION_CHANNELS = 1
"""The toolbox appends one all-zero truncation channel; trackers drop it."""


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
