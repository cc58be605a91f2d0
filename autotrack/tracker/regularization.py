"""Automatic spatio-temporal regularisation (paper section 4.1): response variations -> u, theta."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import scipy.linalg

from autotrack.tracker.dcf import half_spectrum_weights

# The release scales the global variation by 1e-4 before comparing it with phi and using nu.
GLOBAL_VARIATION_SCALE = 1e-4

ThetaRule = Callable[[np.ndarray, int], float]
"""theta for the next ADMM iteration from the current filter (half spectrum) and the iteration."""


def target_region(grid_size: tuple[int, int], region_size: tuple[int, int]) -> tuple[slice, slice]:
    """Rows/cols of the target region in the spatial window (centred as the release centres it)."""
    slices = []
    for n, r in zip(grid_size, region_size, strict=True):
        centre = (n + 1) // 2 + (n + 1) % 2  # 1-based centre of the release
        start = centre - r // 2 - 1
        slices.append(slice(max(start, 0), max(start, 0) + r))
    return slices[0], slices[1]


def base_spatial_window(
    grid_size: tuple[int, int],
    region_size: tuple[int, int],
    outside_value: float,
    inside_value: float,
) -> np.ndarray:
    """STRCF's window u: large outside the target region, tiny inside it (eq. 1)."""
    window = np.full(grid_size, outside_value, dtype=np.float32)
    rows, cols = target_region(grid_size, region_size)
    window[rows, cols] = inside_value
    return window


def local_variation(
    response: np.ndarray,
    displacement: tuple[float, float],
    previous_response: np.ndarray,
    previous_displacement: tuple[float, float],
) -> np.ndarray:
    """Local response variation Pi (eq. 2), centred (zero displacement at the map centre).

    Each map is circularly shifted by its own integer peak displacement so the two peaks
    coincide; Pi = |R_t - R_{t-1}| / |R_{t-1}| elementwise. Division by a near-zero response
    gives inf/NaN entries, which the caller must treat (they make the frame aberrant). float32.
    """
    current, previous = centred_alignment(
        response, displacement, previous_response, previous_displacement
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        return (np.abs(current - previous) / np.abs(previous)).astype(np.float32, copy=False)


def centred_alignment(
    response: np.ndarray,
    displacement: tuple[float, float],
    previous_response: np.ndarray,
    previous_displacement: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray]:
    """Both maps circularly shifted by minus their floored peak and then by half the map, so the
    peaks meet at the centre (eq. 2's alignment, and the release's centring, in one roll)."""

    def roll(values: np.ndarray, peak: tuple[float, float]) -> np.ndarray:
        return np.roll(values, centring_shift(values.shape, peak), axis=(0, 1))

    return roll(response, displacement), roll(previous_response, previous_displacement)


def centring_shift(shape: tuple[int, ...], peak: tuple[float, float]) -> tuple[int, int]:
    """The (rows, cols) circular shift that moves a map's floored peak displacement to the
    centre of the map (`centred_alignment`'s roll)."""
    return shape[0] // 2 - math.floor(peak[0]), shape[1] // 2 - math.floor(peak[1])


def global_variation(variation: np.ndarray) -> float:
    """Global variation eta = ||Pi||_2 * 1e-4 (eq. 2), with MATLAB's matrix 2-norm (the largest
    singular value); inf when Pi has non-finite entries (a blow-up counts as an aberrance)."""
    if not np.isfinite(variation).all():
        return math.inf
    return spectral_norm(variation.astype(np.float64)) * GLOBAL_VARIATION_SCALE


def spectral_norm(matrix: np.ndarray) -> float:
    """The largest singular value of a real float64 matrix: the square root of the largest
    eigenvalue of its Gram matrix, which LAPACK's dsyevr finds alone (the value of
    `np.linalg.norm(matrix, ord=2)` to ~1e-15 relative, at half the time of its full SVD on a
    50 x 50 variation map)."""
    gram = matrix.T @ matrix if matrix.shape[0] >= matrix.shape[1] else matrix @ matrix.T
    size = gram.shape[0]
    largest = scipy.linalg.lapack.dsyevr(gram, compute_v=0, range="I", il=size, iu=size)[0][0]
    return math.sqrt(max(float(largest), 0.0))


def temporal_reference(eta: float, zeta: float, nu: float) -> float:
    """Reference temporal penalty theta_ref = zeta / (1 + log(nu * eta + 1)) (eq. 4)."""
    return float(zeta / (1.0 + np.log(nu * eta + 1.0)))


def is_aberrant(eta: float, phi: float) -> bool:
    """Aberrance test of eq. 4: the filter is not updated when eta >= phi (or eta is not finite)."""
    return not (eta < phi)


def adaptive_spatial_window(
    base_window: np.ndarray,
    variation_centred: np.ndarray,
    region: tuple[slice, slice],
    delta: float,
) -> np.ndarray:
    """ASR (eq. 3): the target region of u becomes delta * log(Pi + 1); outside it stays u.

    The release replaces the region (paper eq. 3 adds to the 1e-3 floor: equivalent up to it).
    Non-finite Pi entries (aberrant frames, where no training happens) are set to the outside
    value so they can never leak into a filter.
    """
    window = base_window.copy()
    with np.errstate(invalid="ignore", over="ignore"):
        region_values = delta * np.log(variation_centred[region] + 1.0)
    outside = float(base_window.max())
    window[region] = np.where(np.isfinite(region_values), region_values, outside)
    return window


def theta_update(
    variant: str, theta_ref: float, filter_prev: np.ndarray, grid_size: tuple[int, int]
) -> ThetaRule:
    """Eq. 13 re-estimation of theta inside ADMM: theta = max(theta_ref - ||g - g_prev||^2 / 2, 0).

    `variant` "paper" takes the full filter-difference energy (on the half spectrum, weighted
    to count the whole one); "release" indexes one element of the difference as the authors'
    code does (MATLAB linear index = channel count); "reference" keeps theta = theta_ref.
    `filter_prev` is the previous frame's filter, (channels, rows, half columns).
    """
    if variant == "reference":
        return lambda g_f, iteration: theta_ref
    if variant == "release":
        channels = filter_prev.shape[0]
        shape = (grid_size[0], grid_size[1], channels)
        row, col, channel = np.unravel_index(channels - 1, shape, order="F")

        def release(g_f: np.ndarray, iteration: int) -> float:
            change = abs(complex(g_f[channel, row, col] - filter_prev[channel, row, col]))
            return max(theta_ref - change**2 / 2.0, 0.0)

        return release
    weights = half_spectrum_weights(grid_size)

    def paper(g_f: np.ndarray, iteration: int) -> float:
        difference = g_f - filter_prev
        energy = float(np.sum((difference.real**2 + difference.imag**2) * weights))
        energy /= grid_size[0] * grid_size[1]
        return max(theta_ref - energy / 2.0, 0.0)

    return paper
