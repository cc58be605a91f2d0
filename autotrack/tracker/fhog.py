"""Felzenszwalb HOG as Piotr Dollar's toolbox computes it, `fhog(I, binSize, nOrients, clip)`, in
vectorised numpy: the reference the compiled `backend.fast_fhog` is tested against.

The AutoTrack release calls `fhog(single(patch), 4, 9)`. Per pixel (only the first
(H//cell)*cell rows and (W//cell)*cell columns are binned):
1. centred differences (one-sided at the image border); of several channels the one with the
   largest squared magnitude (the first among equals);
2. the orientation in [0, 2 pi), from the toolbox's acos table, to one of 2n bins; the
   magnitude / cell^2 spread bilinearly over the 4 nearest cells; border cells times 8/7;
3. contrast-insensitive bins = sums of opposite sensitive bins; each cell normalised by its
   four 2 x 2 blocks' energies, clipped at `clip`, giving 2n + n orientation channels and 4
   texture channels; a last all-zero channel completes the toolbox's 3n + 5.
The toolbox's SSE rcp/rsqrt approximations are taken exactly here (float32).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from autotrack.errors import InputError

ACOS_STEPS = 10000  # the toolbox's acosTable: a[i] ~= acos(i / 10000)
ACOS_PAD = 10
ACOS_OFFSET = ACOS_STEPS + ACOS_PAD
TOOLBOX_PI = np.float32(3.14159265)  # the toolbox's PI (a float literal)
TEXTURE_WEIGHT = np.float32(0.2357)  # ~ 1 / sqrt(18), hogChannels' r


def fhog_channels(n_orients: int = 9) -> int:
    """Channels the toolbox returns: 2n sensitive + n insensitive + 4 texture + 1 zero."""
    return 3 * n_orients + 5


@lru_cache(maxsize=1)
def acos_table() -> np.ndarray:
    """The toolbox's acosTable(): float32 acos(i / 10000) for i in [-10010, 10010), read-only;
    pi below -10000, 0 above 9999, values above pi - 1e-6 clamped there. Index with
    `int(x * 10000) + 10010`."""
    table = np.empty(2 * ACOS_OFFSET, dtype=np.float32)
    steps = np.arange(-ACOS_STEPS, ACOS_STEPS, dtype=np.float32) / np.float32(ACOS_STEPS)
    table[:ACOS_PAD] = TOOLBOX_PI
    table[ACOS_PAD : ACOS_PAD + 2 * ACOS_STEPS] = np.arccos(steps.astype(np.float64))
    table[ACOS_PAD + 2 * ACOS_STEPS :] = 0.0
    limit = TOOLBOX_PI - np.float32(1e-6)
    head = table[: ACOS_OFFSET + ACOS_STEPS // 10]
    head[head > limit] = limit
    table.flags.writeable = False
    return table


def gradients(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(gx, gy) of the strongest channel per pixel: centred differences, one-sided at borders."""
    pixels = np.asarray(image, dtype=np.float32)
    pixels = pixels[:, :, None] if pixels.ndim == 2 else pixels
    gx, gy = np.empty_like(pixels), np.empty_like(pixels)
    for gradient, axis in ((gx, 1), (gy, 0)):
        ahead = np.take(pixels, range(2, pixels.shape[axis]), axis)
        behind = np.take(pixels, range(pixels.shape[axis] - 2), axis)
        middle = [slice(None)] * 3
        middle[axis] = slice(1, -1)
        gradient[tuple(middle)] = (ahead - behind) * np.float32(0.5)
        for end, (a, b) in ((0, (1, 0)), (-1, (-1, -2))):
            edge = [slice(None)] * 3
            edge[axis] = end
            gradient[tuple(edge)] = np.take(pixels, a, axis) - np.take(pixels, b, axis)
    strongest = np.argmax(gx * gx + gy * gy, axis=2)[:, :, None]  # first among equals
    return np.take_along_axis(gx, strongest, 2)[:, :, 0], np.take_along_axis(gy, strongest, 2)[
        :, :, 0
    ]


def orientation_bins(gx: np.ndarray, gy: np.ndarray, n_bins: int) -> np.ndarray:
    """gradHist's hard orientation bin (of `n_bins` over [0, 2 pi)) per pixel, in float32."""
    magnitude = np.sqrt(gx * gx + gy * gy)
    with np.errstate(divide="ignore"):
        inverse = np.minimum(np.float32(1.0) / magnitude, np.float32(1e10))
    cosine = gx * inverse * np.float32(ACOS_STEPS)
    cosine = np.where(gy < 0, -cosine, cosine)
    angle = acos_table()[cosine.astype(np.int64) + ACOS_OFFSET]
    angle = np.where(gy < 0, angle + TOOLBOX_PI, angle)
    per_radian = np.float32(n_bins) / (np.float32(2.0) * TOOLBOX_PI)
    index = (angle * per_radian + np.float32(0.5)).astype(np.int64)
    return np.where(index >= n_bins, 0, index)


def _bilinear_weights(pixels: int, cell: int) -> np.ndarray:
    """(pixels, cells) weights of each pixel's two nearest cells along one axis."""
    cells = pixels // cell
    position = (np.arange(pixels) + 0.5) / cell - 0.5
    first = np.floor(position).astype(np.int64)
    weights = np.zeros((pixels, cells + 2))
    weights[np.arange(pixels), first + 1] = 1.0 - (position - first)
    weights[np.arange(pixels), first + 2] = position - first
    return weights[:, 1 : cells + 1]


def orientation_histogram(image: np.ndarray, cell: int, n_bins: int) -> np.ndarray:
    """(H//cell, W//cell, n_bins) cell histograms of gradient magnitude / cell^2 (gradHist)."""
    gx, gy = gradients(image)
    rows, cols = (gx.shape[0] // cell) * cell, (gx.shape[1] // cell) * cell
    gx, gy = gx[:rows, :cols], gy[:rows, :cols]
    magnitude = np.sqrt(gx * gx + gy * gy).astype(np.float64) / cell**2
    votes = np.zeros((rows, cols, n_bins))
    np.put_along_axis(votes, orientation_bins(gx, gy, n_bins)[:, :, None], magnitude[:, :, None], 2)
    by_row = np.tensordot(_bilinear_weights(rows, cell), votes, axes=(0, 0))
    histogram = np.einsum("ixo,xj->ijo", by_row, _bilinear_weights(cols, cell))
    gain = np.ones(histogram.shape[:2])
    for border in (np.s_[0, :], np.s_[-1, :], np.s_[:, 0], np.s_[:, -1]):
        gain[border] *= 8.0 / 7.0
    return histogram * gain[:, :, None]


def block_normalisers(energy: np.ndarray, cell: int) -> np.ndarray:
    """hogNormMatrix: 1 / sqrt(2 x 2 block energy + eps) on an (hb+1, wb+1) grid; entry
    [i+1, j+1] is the block with top-left cell (i, j); the border filled in the C code's order
    (which matters only for one cell row or column: raw energies then leak, as there)."""
    hb, wb = energy.shape
    norm = np.zeros((hb + 1, wb + 1))
    norm[1:, 1:] = energy
    eps = 1e-4 / 4.0 / cell**4
    blocks = energy[:-1, :-1] + energy[1:, :-1] + energy[:-1, 1:] + energy[1:, 1:]
    norm[1:hb, 1:wb] = 1.0 / np.sqrt(blocks + eps)
    norm[0, 0] = norm[1, 1]
    norm[:, 0] = norm[:, 1]
    norm[hb, 0] = norm[hb - 1, 1]
    norm[0, wb] = norm[1, wb - 1]
    norm[:, wb] = norm[:, wb - 1]
    norm[hb, wb] = norm[hb - 1, wb - 1]
    norm[0, :] = norm[1, :]
    norm[hb, :] = norm[hb - 1, :]
    return norm


def checked_images(images: np.ndarray, image_axes: int) -> np.ndarray:
    """`images` ((..., H, W) with `image_axes` = 2 or 3 axes, or with a channel axis) as
    C-contiguous uint8 or float32 with an explicit channel axis; InputError otherwise."""
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


def check_settings(cell_size: int, n_orients: int, clip: float) -> None:
    """InputError unless the cell and orientation count are positive integers, clip positive."""
    if int(cell_size) != cell_size or cell_size < 1:
        raise InputError(f"fhog cell_size must be a positive integer, got {cell_size}")
    if int(n_orients) != n_orients or n_orients < 1:
        raise InputError(f"fhog n_orients must be a positive integer, got {n_orients}")
    if not (math.isfinite(clip) and clip > 0):
        raise InputError(f"fhog clip must be a positive number, got {clip}")


def fhog(
    image: np.ndarray, cell_size: int = 4, n_orients: int = 9, clip: float = 0.2
) -> np.ndarray:
    """Piotr Dollar's `fhog(single(image), cell_size, n_orients, clip)`: float32 (H//cell,
    W//cell, 3n+5): 2n contrast-sensitive orientations, n insensitive, 4 texture channels and
    one all-zero channel (which the tracker drops). `image` is H x W or H x W x C on its own
    scale (0..255 for 8-bit images)."""
    check_settings(cell_size, n_orients, clip)
    pixels = checked_images(image, 2)
    hb, wb = pixels.shape[0] // cell_size, pixels.shape[1] // cell_size
    out = np.zeros((hb, wb, fhog_channels(n_orients)), np.float32)
    if hb == 0 or wb == 0:
        return out
    sensitive = orientation_histogram(pixels, cell_size, 2 * n_orients)
    insensitive = sensitive[:, :, :n_orients] + sensitive[:, :, n_orients:]
    norm = block_normalisers(np.sum(insensitive**2, axis=2), cell_size)
    blocks = [norm[1:, 1:], norm[:-1, 1:], norm[1:, :-1], norm[:-1, :-1]]  # hogChannels' four
    bins = np.concatenate([sensitive, insensitive], axis=2)
    clipped = np.stack([np.minimum(bins * b[:, :, None], clip) for b in blocks])  # (4, hb, wb, 3n)
    out[:, :, : 3 * n_orients] = 0.5 * clipped.sum(axis=0)
    texture = TEXTURE_WEIGHT * clipped[:, :, :, : 2 * n_orients].sum(axis=3)
    out[:, :, 3 * n_orients : 3 * n_orients + 4] = texture.transpose(1, 2, 0)
    return out
