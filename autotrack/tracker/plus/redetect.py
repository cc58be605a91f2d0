"""Re-detection over a wider region when the tracker's confidence is low (`autotrack+`).

Long-term correlation trackers (LCT, Ma et al. CVPR 2015; the re-detection of MUSTer and of
DR2Track-style UAV trackers) look for the target outside the usual search region once the
detection confidence drops. Here the current filter itself is correlated with the features of a
region `span` times the search region's side, at the filter's own resolution (the frame
resampled by the tracker's scale factor), in one FFT: the response at every placement of the
filter's support, not only the circular shifts of one search patch. The tracker then re-runs its
ordinary detection at the best placement and keeps it only if it is confident there and beats
the peak it had.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft

from autotrack.tracker import dcf
from autotrack.tracker.backend import Backend


def filter_support(
    filter_f: np.ndarray, grid_size: tuple[int, int], cos_window: np.ndarray
) -> np.ndarray:
    """The filter in the spatial domain times the Hann window, (channels, rows, cols).

    Detection correlates the filter with windowed features, sum h (w z) = sum (h w) z, so the
    windowed filter on raw features scores each placement exactly as eq. 16 scores a patch.
    """
    return (dcf.from_spectrum(filter_f, grid_size) * cos_window).astype(np.float32)


def placement_response(filter_spatial: np.ndarray, feature_maps: np.ndarray) -> np.ndarray:
    """Valid correlation of the filter with larger feature maps (channels first).

    R(r, c) = sum_k sum_(i, j) h_k(i, j) z_k(r + i, c + j) for every placement (r, c) of the
    n x m filter inside the M x N maps: the detection response of eq. 16 without the circular
    wrap, so each value is the score of the filter's grid laid at (r, c). Shape (M-n+1, N-m+1).
    """
    channels, rows, cols = filter_spatial.shape
    _, big_rows, big_cols = feature_maps.shape
    if big_rows < rows or big_cols < cols:
        raise ValueError("the feature maps must be at least as large as the filter")
    grid = (big_rows, big_cols)
    filter_f = scipy.fft.rfft2(filter_spatial, s=grid, axes=dcf.GRID_AXES, workers=1)
    maps_f = scipy.fft.rfft2(feature_maps, axes=dcf.GRID_AXES, workers=1)
    correlation = scipy.fft.irfft2(
        np.einsum("krc,krc->rc", np.conj(filter_f), maps_f), s=grid, axes=dcf.GRID_AXES, workers=1
    )
    return correlation[: big_rows - rows + 1, : big_cols - cols + 1]


def wide_search_offset(
    image: np.ndarray,
    position: np.ndarray,
    scale: float,
    window_px: int,
    span: float,
    filter_f: np.ndarray,
    grid_size: tuple[int, int],
    cos_window: np.ndarray,
    backend: Backend,
) -> tuple[np.ndarray, float]:
    """Best target position in a region `span` x the search region, and its raw score.

    `position` is the 1-based (row, col) centre of the search, `window_px` the filter's patch
    side (pixels at the filter's resolution) and `scale` image pixels per patch pixel. Returns
    the best centre as a (row, col) offset from `position`, in image pixels. `backend` samples
    the region and computes its features (the tracker's own).
    """
    cell = backend.params.cell_size
    cells = int(math.ceil(span * window_px / cell))
    side_px = cells * cell
    region = int(dcf.matlab_round(side_px * scale))
    patch = backend.search_patch(image, position, (region, region), (side_px, side_px))
    maps = backend.feature_maps(patch)
    response = placement_response(filter_support(filter_f, grid_size, cos_window), maps)
    best = int(np.argmax(response))
    row, col = divmod(best, response.shape[1])
    # Placement (row, col) puts the filter's centre (its patch centre) at cell row + n/2.
    centre_row = (row + grid_size[0] / 2.0) * cell
    centre_col = (col + grid_size[1] / 2.0) * cell
    offset = (np.array([centre_row, centre_col]) - side_px / 2.0) * (region / side_px)
    return offset, float(response.flat[best])
