"""The correlation filter of the paper, in plain numpy: label, window, ADMM training, detection.

This is the reference: one short function per step, the equation number beside it. The fast
backend (`autotrack.tracker.backend`) computes the same steps with compiled kernels and is
tested against these functions.

Spectra are real-input half spectra (`scipy.fft.rfft2` over the two grid axes, the last axis
halved): every step is per frequency or a real spatial product, so the half spectrum gives the
filter of the release's full spectrum. Arrays are (channels, rows, cols), float32 / complex64.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.fft

from autotrack.params import TrackerParams

GRID_AXES = (-2, -1)


def matlab_round(values: np.ndarray | float) -> np.ndarray:
    """MATLAB's round: halves away from zero (numpy rounds halves to even)."""
    values = np.asarray(values, dtype=np.float64)
    return np.sign(values) * np.floor(np.abs(values) + 0.5)


@lru_cache(maxsize=16)
def centred_frequencies(n: int) -> np.ndarray:
    """Integer frequencies/offsets in FFT order: 0, 1, ..., ceil((n-1)/2), -floor((n-1)/2), ..., -1
    (read-only, cached)."""
    half = (n - 1) // 2
    frequencies = np.roll(np.arange(-half, n - half), -half).astype(np.float64)
    frequencies.flags.writeable = False
    return frequencies


def gaussian_label(grid_size: tuple[int, int], sigma: float) -> np.ndarray:
    """Desired response y: a 2-D Gaussian on the cell grid with its peak at the origin (eq. 1)."""
    rows = centred_frequencies(grid_size[0])[:, None]
    cols = centred_frequencies(grid_size[1])[None, :]
    return np.exp(-0.5 * (rows**2 + cols**2) / sigma**2)


def cosine_window(grid_size: tuple[int, int]) -> np.ndarray:
    """Hann window of the release: MATLAB hann(n + 2) without its two zero end points."""

    def hann_inner(n: int) -> np.ndarray:
        k = np.arange(1, n + 1)
        return 0.5 * (1.0 - np.cos(2.0 * np.pi * k / (n + 1)))

    return np.outer(hann_inner(grid_size[0]), hann_inner(grid_size[1])).astype(np.float32)


def to_spectrum(maps: np.ndarray) -> np.ndarray:
    """Half spectrum of real maps (..., rows, cols) -> complex64 (..., rows, cols // 2 + 1)."""
    return scipy.fft.rfft2(maps, axes=GRID_AXES, workers=1).astype(np.complex64, copy=False)


def from_spectrum(spectrum: np.ndarray, grid_size: tuple[int, int]) -> np.ndarray:
    """Real maps from half spectra (the inverse of `to_spectrum`)."""
    return scipy.fft.irfft2(spectrum, s=grid_size, axes=GRID_AXES, workers=1)


def half_spectrum_weights(grid_size: tuple[int, int]) -> np.ndarray:
    """Multiplicity of each half-spectrum column in the full spectrum (for sums of |.|^2)."""
    weights = np.full(grid_size[1] // 2 + 1, 2.0, dtype=np.float32)
    weights[0] = 1.0
    if grid_size[1] % 2 == 0:
        weights[-1] = 1.0
    return weights


# -- training: ADMM (paper section 4.2) --------------------------------------------------------


@dataclass(frozen=True)
class AdmmSettings:
    """Fixed settings of the ADMM solver (paper section 4.2)."""

    iterations: int
    """ADMM iterations per frame (4)."""
    lambda_spatial: float
    """lambda, the weight of the spatial regulariser (1)."""
    gamma_init: float
    """The penalty gamma of the first iteration (1)."""
    gamma_step: float
    """gamma's growth per iteration (x10)."""
    gamma_max: float
    """gamma's ceiling (10000)."""


def admm_settings(params: TrackerParams) -> AdmmSettings:
    """The ADMM solver's settings from the tracker parameters."""
    return AdmmSettings(
        iterations=params.admm_iterations,
        lambda_spatial=params.admm_lambda,
        gamma_init=params.gamma_init,
        gamma_step=params.gamma_step,
        gamma_max=params.gamma_max,
    )


def g_step(xf, yf, h_f, l_f, g_prev, gamma: float, theta: float, num_cells: int) -> np.ndarray:
    """The g-subproblem per frequency by Sherman-Morrison (eqs. 10-11), as the release writes it:
    g = (q - x (x^H q) / (x^H x + T (gamma + theta))) / (gamma + theta), with
    q = y x / T - l + gamma h + theta g_prev, T = num_cells and l the scaled multiplier."""
    penalty = gamma + theta
    right = yf * xf / num_cells - l_f + gamma * h_f + theta * g_prev  # q
    energy = np.sum(xf.real**2 + xf.imag**2, axis=0)  # x^H x
    projected = np.sum(np.conj(xf) * right, axis=0) / (energy + num_cells * penalty)
    return (right - xf * projected) / penalty


def h_step(g_f, l_f, spatial_window, gamma: float, lambda_spatial: float) -> np.ndarray:
    """The h-subproblem in the spatial domain (eq. 12): h = T / (lambda u^2 + gamma T) .*
    F^-1(gamma (g + l)), returned as a half spectrum."""
    grid_size = spatial_window.shape
    num_cells = grid_size[0] * grid_size[1]
    gain = num_cells / (lambda_spatial * spatial_window**2 + gamma * num_cells)
    h = gain.astype(np.float32) * from_spectrum(gamma * (g_f + l_f), grid_size)
    return to_spectrum(h)


def multiplier_update(l_f, g_f, h_f, gamma: float) -> np.ndarray:
    """The scaled Lagrange multiplier (eq. 14): l <- l + gamma (g - h)."""
    return l_f + gamma * (g_f - h_f)


def next_gamma(gamma: float, settings: AdmmSettings) -> float:
    """The penalty schedule (eq. 15): gamma <- min(gamma_step gamma, gamma_max)."""
    return min(settings.gamma_step * gamma, settings.gamma_max)


def train_filter(
    xf: np.ndarray,
    yf: np.ndarray,
    g_prev: np.ndarray,
    spatial_window: np.ndarray,
    theta: float,
    settings: AdmmSettings,
    theta_rule=None,
) -> tuple[np.ndarray, float]:
    """ADMM on the AutoTrack objective (eqs. 5-15): the filter of this frame and the last theta.

    `theta_rule(g_f, iteration)` re-estimates theta after an iteration's g/h steps (eq. 13),
    or returns None to keep it. As in the release, the last iteration stops after its g-step
    (its h, theta and multiplier would be unused).
    """
    num_cells = spatial_window.shape[0] * spatial_window.shape[1]
    h_f = l_f = np.zeros_like(xf)
    gamma = settings.gamma_init
    for iteration in range(1, settings.iterations + 1):
        g_f = g_step(xf, yf, h_f, l_f, g_prev, gamma, theta, num_cells)
        if iteration == settings.iterations:
            break
        h_f = h_step(g_f, l_f, spatial_window, gamma, settings.lambda_spatial)
        new_theta = None if theta_rule is None else theta_rule(g_f, iteration)
        theta = theta if new_theta is None else float(new_theta)
        l_f = multiplier_update(l_f, g_f, h_f, gamma)
        gamma = next_gamma(gamma, settings)
    return g_f, float(theta)


# -- detection ---------------------------------------------------------------------------------


def detection_response(g_f: np.ndarray, zf: np.ndarray, grid_size: tuple[int, int]) -> np.ndarray:
    """Response map R = F^-1 sum_k conj(g_k) z_k (eq. 16), peak at the origin if no motion."""
    return from_spectrum(np.sum(np.conj(g_f) * zf, axis=0), grid_size)


def newton_peak(response: np.ndarray, iterations: int) -> tuple[float, float, float]:
    """Sub-pixel peak of a response map: Newton's method on its Fourier series (the release's).

    Starts at the integer maximum and keeps it if Newton lowers the interpolated score.
    Returns (row displacement, col displacement, peak score) in cells, wrapped to [-n/2, n/2).
    """
    rows, cols = response.shape
    response_f = scipy.fft.fft2(response, workers=1).astype(np.complex128)
    peak_row, peak_col = divmod(int(response.argmax()), cols)
    init_score = float(response[peak_row, peak_col])
    row_half, col_half = (rows - 1) // 2, (cols - 1) // 2
    init_y = 2.0 * math.pi * ((peak_row + row_half) % rows - row_half) / rows
    init_x = 2.0 * math.pi * ((peak_col + col_half) % cols - col_half) / cols
    ky, kx = centred_frequencies(rows), centred_frequencies(cols)
    pos_y, pos_x = init_y, init_x
    for _ in range(iterations):
        step = _newton_step(response_f, ky, kx, pos_y, pos_x)
        if step is None:
            break
        pos_y, pos_x = pos_y - step[0], pos_x - step[1]
    score = float((np.exp(1j * ky * pos_y) @ response_f @ np.exp(1j * kx * pos_x)).real)
    score /= rows * cols
    if not math.isfinite(score) or score < init_score:
        pos_y, pos_x, score = init_y, init_x, init_score
    turn = 2.0 * math.pi
    disp_row = ((pos_y + math.pi) % turn - math.pi) / turn * rows
    disp_col = ((pos_x + math.pi) % turn - math.pi) / turn * cols
    return float(disp_row), float(disp_col), float(score)


def _newton_step(response_f, ky, kx, pos_y, pos_x) -> tuple[float, float] | None:
    """H^-1 grad of the response's Fourier series at (pos_y, pos_x) radians; None when the
    Hessian is singular (the release's expressions, its `ival` term included)."""
    exp_iky, exp_ikx = np.exp(1j * ky * pos_y), np.exp(1j * kx * pos_x)
    along_y, along_x = exp_iky @ response_f, response_f @ exp_ikx
    grad_y = -((ky * exp_iky) @ along_x).imag
    grad_x = -(along_y @ (kx * exp_ikx)).imag
    ival = 1j * (exp_iky @ along_x)
    h_yy = (-((ky**2 * exp_iky) @ along_x) + ival).real
    h_xx = (-(along_y @ (kx**2 * exp_ikx)) + ival).real
    h_xy = -((ky * exp_iky) @ (response_f @ (kx * exp_ikx))).real
    det = h_yy * h_xx - h_xy * h_xy
    if det == 0.0 or not math.isfinite(det):
        return None
    return (h_xx * grad_y - h_xy * grad_x) / det, (h_yy * grad_x - h_xy * grad_y) / det


def shift_spectrum(
    xf: np.ndarray, shift_rows: float, shift_cols: float, grid_size: tuple[int, int]
) -> np.ndarray:
    """Feature maps translated by (shift_rows, shift_cols) cells in the Fourier domain: the
    release trains on the detection features moved to the new position, not on a new patch."""
    ky = centred_frequencies(grid_size[0])
    kx = np.arange(xf.shape[-1], dtype=np.float64)
    phase_rows = np.exp(1j * (2.0 * np.pi * shift_rows / grid_size[0]) * ky).astype(np.complex64)
    phase_cols = np.exp(1j * (2.0 * np.pi * shift_cols / grid_size[1]) * kx).astype(np.complex64)
    return xf * (phase_rows[:, None] * phase_cols[None, :])


def centred_response(response: np.ndarray) -> np.ndarray:
    """The response with zero displacement at the map centre, as float32."""
    return np.fft.fftshift(response).astype(np.float32)
