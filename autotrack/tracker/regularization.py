"""Automatic spatio-temporal regularisation (paper section 4.1): response variations -> u, theta."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numba import njit

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
    gives inf/NaN entries, which the caller must treat (they make the frame aberrant).
    Computed in one compiled pass: numpy's `np.abs(a - b) / np.abs(b)` on the two maps rolled
    as `centred_alignment` rolls them, bit for bit (float32 maps give float32 arithmetic).
    """
    shift, previous_shift = _centring_shifts(response.shape, displacement, previous_displacement)
    variation = np.empty(response.shape, np.float32)
    _centred_variation(response, previous_response, *shift, *previous_shift, variation)
    return variation


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _centred_variation(response, previous, shift_r, shift_c, previous_r, previous_c, out):
    """out = |roll(response) - roll(previous)| / |roll(previous)|, each map rolled by its own
    (rows, cols) shift as np.roll does (out[i] = map[(i - shift) mod n])."""
    rows, cols = response.shape
    shift_c, previous_c = shift_c % cols, previous_c % cols
    for r in range(rows):
        values = response[(r - shift_r) % rows]
        befores = previous[(r - previous_r) % rows]
        for c in range(cols):
            column = c - shift_c if c >= shift_c else c - shift_c + cols
            previous_column = c - previous_c if c >= previous_c else c - previous_c + cols
            value, before = values[column], befores[previous_column]
            out[r, c] = abs(value - before) / abs(before)


def _centring_shifts(
    shape: tuple[int, ...],
    displacement: tuple[float, float],
    previous_displacement: tuple[float, float],
) -> tuple[tuple[int, int], tuple[int, int]]:
    """The (rows, cols) roll of each map that puts both peaks at the centre (eq. 2)."""
    centre = (shape[0] // 2, shape[1] // 2)
    shift = (centre[0] - math.floor(displacement[0]), centre[1] - math.floor(displacement[1]))
    previous_shift = (
        centre[0] - math.floor(previous_displacement[0]),
        centre[1] - math.floor(previous_displacement[1]),
    )
    return shift, previous_shift


def centred_alignment(
    response: np.ndarray,
    displacement: tuple[float, float],
    previous_response: np.ndarray,
    previous_displacement: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray]:
    """Both maps circularly shifted by minus their floored peak and then by half the map, so the
    peaks meet at the centre: one roll per map instead of aligning first and centring the
    variation after (element-wise maths commutes with the shift, so Pi is the same bit for bit).
    """
    shift, previous_shift = _centring_shifts(response.shape, displacement, previous_displacement)
    return (
        np.roll(response, shift, axis=(0, 1)),
        np.roll(previous_response, previous_shift, axis=(0, 1)),
    )


def global_variation(variation: np.ndarray) -> float:
    """Global variation eta = ||Pi||_2 * 1e-4, with MATLAB's matrix 2-norm (largest singular value).

    Returns inf when Pi has non-finite entries (a numerical blow-up counts as an aberrance).
    The norm is `spectral_norm`'s, within a few units in the last place of LAPACK's singular
    value (tests/test_update_glue.py): eta reaches the filter only through float32 penalties
    and the test against phi, so the tracking is the same.
    """
    return spectral_norm(variation) * GLOBAL_VARIATION_SCALE


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def spectral_norm(matrix):
    """Largest singular value of a real matrix in float64 (inf if any entry is not finite).

    sqrt of the largest eigenvalue of the Gram matrix: Householder tridiagonalisation, then
    Sturm-sequence multisection (LAPACK's dstebz counting, eight points a pass). Within
    ~2e-15 relative of LAPACK's gesdd on the trackers' 50 x 50 variation maps, at a third of
    its time (~45 against ~130 us plus numpy's wrapper, `np.linalg.svd(compute_uv=False)`,
    which a frame of four targets called four times).
    """
    rows, cols = matrix.shape
    for r in range(rows):
        for c in range(cols):
            if not math.isfinite(matrix[r, c]):
                return math.inf
    if rows == 0 or cols == 0:
        return 0.0
    gram = _gram_matrix(matrix)
    size = gram.shape[0]
    diagonal = np.empty(size)
    off_diagonal = np.zeros(size)
    _tridiagonalise(gram, diagonal, off_diagonal)
    return math.sqrt(max(_largest_tridiagonal_eigenvalue(diagonal, off_diagonal), 0.0))


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _gram_matrix(matrix):
    """float64 A^T A, or A A^T when A is wide (the smaller of the two), in full."""
    rows, cols = matrix.shape
    wide = cols > rows
    size, count = (rows, cols) if wide else (cols, rows)
    vectors = np.empty((count, size))  # the Gram matrix's index along each contiguous row
    for r in range(rows):
        for c in range(cols):
            if wide:
                vectors[c, r] = np.float64(matrix[r, c])
            else:
                vectors[r, c] = np.float64(matrix[r, c])
    gram = np.zeros((size, size))
    for k in range(0, count - 1, 2):  # two outer products a pass: half the row traffic
        first, second = vectors[k], vectors[k + 1]
        for i in range(size):
            row, a, b = gram[i], first[i], second[i]
            for j in range(size):
                row[j] += a * first[j] + b * second[j]
    if count % 2 == 1:
        last = vectors[count - 1]
        for i in range(size):
            row, a = gram[i], last[i]
            for j in range(size):
                row[j] += a * last[j]
    return gram


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _tridiagonalise(gram, diagonal, off_diagonal):
    """Householder reduction of a symmetric matrix (overwritten) to tridiagonal form.

    Every loop runs over views from index 0, so the compiler vectorises it (no negative-index
    handling); the product with the reflector is taken column by column (axpy form).
    """
    size = gram.shape[0]
    reflector_buffer = np.empty(size)
    product_buffer = np.empty(size)
    for k in range(size - 2):
        start = k + 1
        length = size - start
        column = gram[k, start:]  # symmetric: row k is column k
        alpha = column[0]
        tail = 0.0
        for i in range(1, length):
            tail += column[i] * column[i]
        if tail == 0.0:
            off_diagonal[k] = alpha
            continue
        norm = math.sqrt(alpha * alpha + tail)
        beta = -norm if alpha >= 0.0 else norm
        off_diagonal[k] = beta
        tau = (beta - alpha) / beta
        reflector = reflector_buffer[:length]  # v with v[0] = 1: H = I - tau v v^T
        product = product_buffer[:length]
        reflector[0] = 1.0
        pivot = alpha - beta
        for i in range(1, length):
            reflector[i] = column[i] / pivot
        for i in range(length):
            product[i] = 0.0
        for j in range(length):
            row, weight = gram[start + j, start:], tau * reflector[j]
            for i in range(length):
                product[i] += weight * row[i]
        dot = 0.0
        for i in range(length):
            dot += product[i] * reflector[i]
        half = 0.5 * tau * dot
        for i in range(length):
            product[i] -= half * reflector[i]
        for i in range(length):  # A -= v w^T + w v^T
            row, v_i, w_i = gram[start + i, start:], reflector[i], product[i]
            for j in range(length):
                row[j] -= v_i * product[j] + w_i * reflector[j]
    for i in range(size):
        diagonal[i] = gram[i, i]
    if size >= 2:
        off_diagonal[size - 2] = gram[size - 1, size - 2]


_SECTION_POINTS = 8
"""Points of the bracket tested per multisection pass (vectorised across them)."""
_PIVOT_MINIMUM = 1e-300


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _largest_tridiagonal_eigenvalue(diagonal, off_diagonal):
    """Largest eigenvalue of a symmetric tridiagonal matrix to the last bit of its bracket.

    The bracket starts at [max diagonal, Gershgorin's bound]; each pass counts the eigenvalues
    below eight points at once (LDL^T pivots' signs) and keeps the sub-interval holding the
    largest, then bisects once the points no longer fit between the ends.
    """
    size = diagonal.size
    low = -math.inf
    high = -math.inf
    for i in range(size):
        radius = (abs(off_diagonal[i - 1]) if i > 0 else 0.0) + (
            abs(off_diagonal[i]) if i < size - 1 else 0.0
        )
        high = max(high, diagonal[i] + radius)
        low = max(low, diagonal[i])
    squared = np.empty(size)
    for i in range(size - 1):
        squared[i] = off_diagonal[i] * off_diagonal[i]
    points = np.empty(_SECTION_POINTS)
    pivots = np.empty(_SECTION_POINTS)
    below = np.empty(_SECTION_POINTS, np.int64)
    while True:
        step = (high - low) / (_SECTION_POINTS + 1)
        for lane in range(_SECTION_POINTS):
            points[lane] = low + step * (lane + 1)
        if not (points[0] > low and points[_SECTION_POINTS - 1] < high):
            middle = 0.5 * (low + high)
            if middle <= low or middle >= high:
                return high
            for lane in range(_SECTION_POINTS):
                points[lane] = middle
        for lane in range(_SECTION_POINTS):
            pivot = diagonal[0] - points[lane]
            if abs(pivot) < _PIVOT_MINIMUM:
                pivot = -_PIVOT_MINIMUM
            pivots[lane] = pivot
            below[lane] = 1 if pivot < 0.0 else 0
        for i in range(1, size):
            value, coupling = diagonal[i], squared[i - 1]
            for lane in range(_SECTION_POINTS):
                pivot = value - points[lane] - coupling / pivots[lane]
                if abs(pivot) < _PIVOT_MINIMUM:
                    pivot = -_PIVOT_MINIMUM
                pivots[lane] = pivot
                below[lane] += 1 if pivot < 0.0 else 0
        new_low, new_high = low, high
        for lane in range(_SECTION_POINTS):
            if below[lane] == size:  # every eigenvalue lies below this point
                new_high = min(new_high, points[lane])
            else:
                new_low = max(new_low, points[lane])
        low, high = new_low, new_high


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
