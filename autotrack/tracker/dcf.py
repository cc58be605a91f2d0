"""The correlation filter: label, window, ADMM training and detection.

All spectra are real-input half spectra (pocketfft's `rfft2` over the two grid axes, the last grid
axis halved). Every operation of the release is per frequency or a real-valued spatial product,
so the half spectrum gives the same filter as the release's full complex spectrum (up to float
rounding and the Nyquist bin, which a real signal forces to be real).

Arrays are laid out (channels, rows, cols) on the cell grid, float32 / complex64, so that every
FFT runs over contiguous memory.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit

from autotrack.tracker import admm_kernels, fft_plans, pocketfft
from autotrack.tracker.fft_plans import pyfftw


def matlab_round(values: np.ndarray | float) -> np.ndarray:
    """MATLAB's round: halves away from zero (numpy rounds halves to even)."""
    values = np.asarray(values, dtype=np.float64)
    return np.sign(values) * np.floor(np.abs(values) + 0.5)


@lru_cache(maxsize=16)
def centred_frequencies(n: int) -> np.ndarray:
    """Integer frequencies/offsets in FFT order: 0, 1, ..., ceil((n-1)/2), -floor((n-1)/2), ..., -1.

    Read-only and cached: every frame asks for the same few grid sizes.
    """
    half = (n - 1) // 2
    frequencies = np.roll(np.arange(-half, n - half), -half).astype(np.float64)
    frequencies.flags.writeable = False
    return frequencies


@lru_cache(maxsize=16)
def _squared_frequencies(n: int) -> np.ndarray:
    squared = centred_frequencies(n) ** 2
    squared.flags.writeable = False
    return squared


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


def to_spectrum(features: np.ndarray) -> np.ndarray:
    """Half spectrum of real maps (..., rows, cols) -> complex64 (..., rows, cols // 2 + 1)."""
    return pocketfft.rfft2(features).astype(np.complex64, copy=False)


def from_spectrum(spectrum: np.ndarray, grid_size: tuple[int, int]) -> np.ndarray:
    """Real maps from half spectra (the inverse of `to_spectrum`)."""
    return pocketfft.irfft2(spectrum, grid_size)


class SpectrumTransform:
    """Planned FFTW real transforms of (channels, rows, cols) float32 maps, one thread.

    The hot path of a tracker runs 2 * admm_iterations - 1 multi-channel transforms per frame
    of a fixed shape. The plans are searched once per machine and shape and kept as FFTW wisdom
    on disk (`fft_plans`), so every tracker, thread and child process of this machine uses the
    same plans (the same rounding); estimated plans when that file cannot be used.
    """

    def __init__(self, channels: int, grid_size: tuple[int, int]) -> None:
        self.grid_size = grid_size
        rows, cols = grid_size
        plans = fft_plans.plans_for(channels, grid_size)
        self.effort = plans.effort
        self._forward = plans.forward
        self._inverse = plans.inverse
        self._spectrum_shape = (channels, rows, cols // 2 + 1)
        # The h-step's own forward plan on its own buffers (the same plan as `_forward`, so the
        # same rounding): its input is written in place by a kernel, and `forward` re-targeting
        # `_forward`'s output array cannot touch a live h spectrum.
        self._h_forward = plans.h_forward
        self._workspace: admm_kernels.AdmmWorkspace | None = None

    def forward(self, maps: np.ndarray) -> np.ndarray:
        """Half spectra of real maps (a new complex64 array)."""
        out = pyfftw.empty_aligned(self._spectrum_shape, np.complex64)
        return self._forward(maps, out)

    @property
    def input_maps(self) -> np.ndarray:
        """The forward plan's own float32 (channels, rows, cols) input buffer: maps written here
        (`features.feature_maps(..., out=transform.input_maps)` writes the windowed features
        channel-first) are transformed by `forward(transform.input_maps)` without a copy."""
        return self._forward.input_array

    def inverse_scratch(self, spectrum: np.ndarray) -> np.ndarray:
        """Real maps of half spectra, in a buffer the next `inverse_scratch` call overwrites."""
        return self._inverse(spectrum)

    def workspace(self) -> admm_kernels.AdmmWorkspace:
        """The ADMM training's buffers for spectra of this shape (made on first use)."""
        if self._workspace is None:
            self._workspace = admm_kernels.AdmmWorkspace(
                self._spectrum_shape, grid_size=self.grid_size
            )
        return self._workspace

    def project(
        self, g_f: np.ndarray, l_f: np.ndarray, gamma: float, gain: np.ndarray
    ) -> np.ndarray:
        """F(gain * F^-1(gamma (g + l))), the h-step (eq. 12), in the transforms' own buffers.

        Returns a buffer the next `project` call overwrites.
        """
        admm_kernels.scaled_sum(g_f, l_f, np.float32(gamma), self.h_step_input)
        return self.project_input(gain)

    @property
    def h_step_input(self) -> np.ndarray:
        """The inverse plan's own complex64 input buffer: gamma (g + l) written here (by
        `project`, or by the training's g-step as it computes g) is what `project_input`
        transforms."""
        return self._inverse.input_array

    def project_input(self, gain: np.ndarray) -> np.ndarray:
        """F(gain * F^-1(`h_step_input`)), in a buffer the next projection overwrites."""
        maps, scale = fft_plans.inverse_unscaled(self._inverse)  # on its own buffers
        admm_kernels.apply_gain(maps, scale, gain, self._h_forward.input_array)
        return self._h_forward()


def half_spectrum_weights(grid_size: tuple[int, int]) -> np.ndarray:
    """Multiplicity of each half-spectrum column in the full spectrum (for sums of |.|^2)."""
    n_cols = grid_size[1] // 2 + 1
    weights = np.full(n_cols, 2.0, dtype=np.float32)
    weights[0] = 1.0
    if grid_size[1] % 2 == 0:
        weights[-1] = 1.0
    return weights


@dataclass(frozen=True)
class AdmmSettings:
    """Fixed settings of the ADMM solver (paper section 4.2)."""

    iterations: int
    lambda_spatial: float
    gamma_init: float
    gamma_step: float
    gamma_max: float


def solve_g_step(
    xf: np.ndarray,
    yf: np.ndarray,
    h_f: np.ndarray,
    l_f: np.ndarray,
    g_prev: np.ndarray,
    s_xx: np.ndarray,
    s_gx_prev: np.ndarray,
    gamma: float,
    theta: float,
    num_cells: int,
    zero_start: bool = False,
    *,
    multiplier_update: tuple[np.ndarray, float, np.ndarray] | None = None,
    h_step_input: tuple[float, np.ndarray] | None = None,
) -> np.ndarray:
    """Sherman-Morrison closed form of the g-subproblem, per frequency (eqs. 10-11).

    Per frequency j it solves (x x^H / T + (gamma + theta) I) g = y x / T - l + gamma h +
    theta g_prev, written as the release writes it (l is its scaled multiplier, T = num_cells).
    `s_xx` = sum_k |x_k|^2 and `s_gx_prev` = sum_k conj(x_k) g_prev_k are constant within a
    frame and passed in precomputed. `zero_start` says h and l are all zero (ADMM's first
    iteration): their sums over channels are then not computed.

    The neighbouring ADMM steps can run in the same passes over the spectra, with results
    those of the separate steps bit for bit. `multiplier_update` (g', gamma', out): first
    l' = l + gamma' (g' - h) into `out` (eq. 14 of the previous iteration), which the g-step
    then uses as its l. `h_step_input` (gamma, out): also writes gamma (g + l) into `out`, the
    h-step's input (eq. 12).
    """
    g_last, multiplier_gamma, l_out = (
        (_by_channel(multiplier_update[0]), multiplier_update[1], _by_channel(multiplier_update[2]))
        if multiplier_update is not None
        else (admm_kernels.NO_SPECTRA, 0.0, admm_kernels.NO_SPECTRA)
    )
    sum_gamma, sum_out = (
        (h_step_input[0], _by_channel(h_step_input[1]))
        if h_step_input is not None
        else (0.0, admm_kernels.NO_SPECTRA)
    )
    g_f = np.empty(xf.shape, xf.dtype)  # C-contiguous, so `_by_channel` is a view of it
    admm_kernels.g_step_kernel(
        _by_channel(xf),
        yf.reshape(-1),
        _by_channel(h_f),
        _by_channel(l_f),
        _by_channel(g_prev),
        s_xx.reshape(-1),
        s_gx_prev.reshape(-1),
        float(gamma),
        float(theta),
        num_cells,
        bool(zero_start),
        _by_channel(g_f),
        g_last,
        np.float32(multiplier_gamma),
        l_out,
        np.float32(sum_gamma),
        sum_out,
    )
    return g_f


def _by_channel(spectra: np.ndarray) -> np.ndarray:
    """(channels, rows, cols) as (channels, rows * cols): a view of a C-contiguous array (a
    copy of any other, which only inputs may be)."""
    return spectra.reshape(spectra.shape[0], -1)


def solve_h_step(
    g_f: np.ndarray,
    l_f: np.ndarray,
    spatial_window: np.ndarray,
    gamma: float,
    lambda_spatial: float,
    transform: SpectrumTransform,
) -> np.ndarray:
    """Closed form of the h-subproblem in the spatial domain, returned as a half spectrum (eq. 12).

    The result lives in `transform`'s buffer, overwritten by the next h-step.
    """
    gain = _h_step_gain(spatial_window, gamma, lambda_spatial, transform)
    return transform.project(g_f, l_f, gamma, gain)


def _h_step_gain(
    spatial_window: np.ndarray, gamma: float, lambda_spatial: float, transform: SpectrumTransform
) -> np.ndarray:
    """The h-step's per-cell gain T / (lambda u^2 + gamma T), T = the number of cells (eq. 12)."""
    num_cells = transform.grid_size[0] * transform.grid_size[1]
    # Python numbers act as float32 beside a float32 window (numpy scalars would not).
    scalars = type(lambda_spatial) in (float, int) and type(gamma) in (float, int)
    if (
        scalars
        and spatial_window.dtype == np.float32
        and spatial_window.shape == transform.grid_size
    ):
        gain = transform.workspace().gain  # the numpy expression below, in one compiled pass
        admm_kernels.h_step_gain(
            spatial_window, float(lambda_spatial), float(gamma), num_cells, gain
        )
        return gain
    gain = num_cells / (lambda_spatial * spatial_window**2 + gamma * num_cells)
    return gain.astype(np.float32)


def train_filter(
    xf: np.ndarray,
    yf: np.ndarray,
    g_prev: np.ndarray,
    spatial_window: np.ndarray,
    theta_start: float,
    settings: AdmmSettings,
    transform: SpectrumTransform,
    theta_of_filter=None,
) -> tuple[np.ndarray, float]:
    """ADMM on the AutoTrack objective (eqs. 5-15); returns the filter and the last theta used.

    `theta_of_filter(g_f, iteration)` re-estimates theta after the g/h steps of an iteration
    (eq. 13); it returns None to keep theta unchanged.

    Each g-step also takes the previous multiplier update (eq. 14) and writes the h-step's input
    (`solve_g_step`'s keyword arguments); the multiplier alternates between two buffers (no
    in-place kernel call).
    """
    num_cells = transform.grid_size[0] * transform.grid_size[1]
    work = transform.workspace()
    g_f = h_f = l_f = work.zeros  # h and the multiplier start at 0; g is set first
    s_xx, s_gx_prev = work.s_xx, work.s_gx
    admm_kernels.training_sums(
        _by_channel(xf), _by_channel(g_prev), s_xx.reshape(-1), s_gx_prev.reshape(-1)
    )
    gamma = float(settings.gamma_init)
    theta = float(theta_start)
    multiplier_update = None  # (g, gamma, buffer) of the update eq. 14 still owes
    for iteration in range(1, settings.iterations + 1):
        last = iteration == settings.iterations  # its h, theta and multiplier would be unused
        g_f = solve_g_step(
            xf,
            yf,
            h_f,
            l_f,
            g_prev,
            s_xx,
            s_gx_prev,
            gamma,
            theta,
            num_cells,
            iteration == 1,
            multiplier_update=multiplier_update,
            h_step_input=None if last else (gamma, transform.h_step_input),
        )
        if multiplier_update is not None:
            l_f = multiplier_update[2]
        if last:
            break
        gain = _h_step_gain(spatial_window, gamma, settings.lambda_spatial, transform)
        h_f = transform.project_input(gain)
        if theta_of_filter is not None:
            new_theta = theta_of_filter(g_f, iteration)
            if new_theta is not None:
                theta = float(new_theta)
        multiplier_update = (g_f, gamma, work.multipliers[iteration % 2])
        gamma = min(settings.gamma_step * gamma, settings.gamma_max)
    return g_f, theta


def detection_response(g_f: np.ndarray, zf: np.ndarray, grid_size: tuple[int, int]) -> np.ndarray:
    """Response map R = F^-1 sum_k conj(g_k) z_k (eq. 16), real, peak at the origin if no motion."""
    return from_spectrum(correlation_spectrum(g_f, zf), grid_size)


def correlation_spectrum(g_f: np.ndarray, zf: np.ndarray) -> np.ndarray:
    """sum_k conj(g_k) z_k per frequency: `np.einsum("krc,krc->rc", np.conj(g_f), zf)` in one
    compiled pass, in its operations (complex64, each product and sum rounded on its own, the
    channels added in order), without the conjugated copy."""
    out = np.empty(zf.shape[1:], np.complex64)
    _correlation_kernel(g_f, zf, out)
    return out


@njit(cache=True, nogil=True, fastmath=False)
def _correlation_kernel(g_f, zf, out):
    channels, rows, cols = zf.shape
    out[:] = 0
    for k in range(channels):
        for r in range(rows):
            for c in range(cols):
                g, z, total = g_f[k, r, c], zf[k, r, c], out[r, c]
                g_re, g_im = g.real, -g.imag  # conj(g)
                re = g_re * z.real - g_im * z.imag
                im = g_re * z.imag + g_im * z.real
                out[r, c] = complex(re + total.real, im + total.imag)


def centred_response(response: np.ndarray) -> np.ndarray:
    """The response with zero displacement at the map centre, as float32:
    `np.fft.fftshift(response).astype(np.float32)` in one compiled copy."""
    centred = np.empty(response.shape, np.float32)
    _half_rolled(response, centred)
    return centred


@njit(cache=True, nogil=True)
def _half_rolled(values, out):
    """out = np.roll(values, (rows // 2, cols // 2), axis=(0, 1)), cast to out's type."""
    rows, cols = values.shape
    shift_r, shift_c = rows // 2, cols // 2
    for r in range(rows):
        source = values[r - shift_r if r >= shift_r else r - shift_r + rows]
        for c in range(cols):
            out[r, c] = source[c - shift_c if c >= shift_c else c - shift_c + cols]


@njit(cache=True, nogil=True, fastmath=False)
def _newton_kernel(response_f, ky, kx, ky_sq, kx_sq, pos_y, pos_x, iterations):
    """Newton's iterations on the Fourier series of a response (the release's, in loops): the
    peak position (radians per axis) and the interpolated score times rows * cols."""
    rows, cols = response_f.shape
    exp_iky = np.exp(1j * ky * pos_y)
    exp_ikx = np.exp(1j * kx * pos_x)
    for _ in range(iterations):
        y_resp = np.zeros(cols, np.complex128)  # exp_iky @ F
        resp_x = np.zeros(rows, np.complex128)  # F @ exp_ikx
        resp_kx = np.zeros(rows, np.complex128)  # F @ (kx exp_ikx)
        kx_exp = kx * exp_ikx  # the same products the loop took per row, taken once
        for r in range(rows):
            for c in range(cols):
                value = response_f[r, c]
                y_resp[c] += exp_iky[r] * value
                resp_x[r] += value * exp_ikx[c]
                resp_kx[r] += value * kx_exp[c]
        grad_y_sum = ival_sum = h_yy_sum = h_xy_sum = 0j
        for r in range(rows):
            ky_exp = ky[r] * exp_iky[r]
            grad_y_sum += ky_exp * resp_x[r]
            ival_sum += exp_iky[r] * resp_x[r]
            h_yy_sum += (ky_sq[r] * exp_iky[r]) * resp_x[r]
            h_xy_sum += ky_exp * resp_kx[r]
        grad_x_sum = h_xx_sum = 0j
        for c in range(cols):
            grad_x_sum += y_resp[c] * (kx[c] * exp_ikx[c])
            h_xx_sum += y_resp[c] * (kx_sq[c] * exp_ikx[c])
        grad_y, grad_x = -grad_y_sum.imag, -grad_x_sum.imag
        ival = 1j * ival_sum
        h_yy = (-h_yy_sum + ival).real
        h_xx = (-h_xx_sum + ival).real
        h_xy = -h_xy_sum.real
        det = h_yy * h_xx - h_xy * h_xy
        if det == 0.0 or not np.isfinite(det):
            break
        pos_y = pos_y - (h_xx * grad_y - h_xy * grad_x) / det
        pos_x = pos_x - (h_yy * grad_x - h_xy * grad_y) / det
        exp_iky = np.exp(1j * ky * pos_y)
        exp_ikx = np.exp(1j * kx * pos_x)
    score = 0j
    for r in range(rows):
        row_sum = 0j
        for c in range(cols):
            row_sum += response_f[r, c] * exp_ikx[c]
        score += exp_iky[r] * row_sum
    return pos_y, pos_x, score.real


def newton_peak(response: np.ndarray, iterations: int) -> tuple[float, float, float]:
    """Sub-pixel peak of a response map by Newton's method on its Fourier series.

    Starts at the integer maximum; keeps it if Newton lowers the interpolated score.
    Returns (row displacement, col displacement, peak score) in cells, displacements wrapped to
    [-n/2, n/2).
    """
    rows, cols = response.shape
    response_f = pocketfft.fft2(response).astype(np.complex128)
    peak_index = int(response.argmax())
    peak_row, peak_col = divmod(peak_index, cols)
    init_score = float(response[peak_row, peak_col])
    row_half = (rows - 1) // 2
    col_half = (cols - 1) // 2
    trans_row = (peak_row + row_half) % rows - row_half
    trans_col = (peak_col + col_half) % cols - col_half
    init_y = 2.0 * math.pi * trans_row / rows
    init_x = 2.0 * math.pi * trans_col / cols
    pos_y, pos_x, score = _newton_kernel(
        response_f,
        centred_frequencies(rows),
        centred_frequencies(cols),
        _squared_frequencies(rows),
        _squared_frequencies(cols),
        init_y,
        init_x,
        int(iterations),
    )
    score /= rows * cols
    if not math.isfinite(score) or score < init_score:
        pos_y, pos_x, score = init_y, init_x, init_score
    turn = 2.0 * math.pi
    disp_row = ((pos_y + math.pi) % turn - math.pi) / turn * rows  # np.mod's value for floats
    disp_col = ((pos_x + math.pi) % turn - math.pi) / turn * cols
    return float(disp_row), float(disp_col), float(score)


def shift_spectrum(
    xf: np.ndarray, shift_rows: float, shift_cols: float, grid_size: tuple[int, int]
) -> np.ndarray:
    """Translate feature maps by (shift_rows, shift_cols) cells in the Fourier domain.

    Used to train on the detection features moved to the new target position instead of
    extracting a new patch (release behaviour).
    """
    ky = centred_frequencies(grid_size[0])
    kx = np.arange(xf.shape[-1], dtype=np.float64)
    phase_rows = np.exp(1j * (2.0 * np.pi * shift_rows / grid_size[0]) * ky).astype(np.complex64)
    phase_cols = np.exp(1j * (2.0 * np.pi * shift_cols / grid_size[1]) * kx).astype(np.complex64)
    phase = phase_rows[:, None] * phase_cols[None, :]
    if xf.dtype != np.complex64:
        return xf * phase
    shifted = np.empty(xf.shape, np.complex64)  # C-contiguous, so `_by_channel` is a view
    admm_kernels.shifted_spectrum(_by_channel(xf), phase.reshape(-1), _by_channel(shifted))
    return shifted
