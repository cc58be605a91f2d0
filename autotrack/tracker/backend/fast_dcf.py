"""The ADMM training and detection of `dcf` in compiled kernels (the fast backend).

The same steps as the reference (`autotrack.tracker.dcf`), fused into fewer passes: each g-step
also takes the previous iteration's multiplier update (eq. 14) and writes the h-step's input
gamma (g + l) (eq. 12), the per-frequency sums constant within a frame are taken once, and the
buffers are kept between frames. tests/test_backend.py checks every function here against the
reference on real sequences.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import scipy.fft
from numba import njit

from autotrack.tracker.backend import admm_kernels
from autotrack.tracker.dcf import (
    AdmmSettings,
    centred_frequencies,
    from_spectrum,
    next_gamma,
    to_spectrum,
)


@lru_cache(maxsize=16)
def _squared_frequencies(n: int) -> np.ndarray:
    squared = centred_frequencies(n) ** 2
    squared.flags.writeable = False
    return squared


class SpectrumTransform:
    """Real transforms of (channels, rows, cols) float32 maps (scipy.fft, one thread) with the
    buffers one tracker's training reuses frame after frame."""

    def __init__(self, channels: int, grid_size: tuple[int, int]) -> None:
        self.grid_size = grid_size
        rows, cols = grid_size
        self._spectrum_shape = (channels, rows, cols // 2 + 1)
        self.input_maps = np.empty((channels, rows, cols), np.float32)
        """Maps written here (`features.feature_maps(..., out=transform.input_maps)`) are
        transformed by `forward(transform.input_maps)`."""
        self.h_step_input = np.empty(self._spectrum_shape, np.complex64)
        """gamma (g + l), written by the training's g-step as it computes g: what
        `project_input` transforms."""
        self._workspace: admm_kernels.AdmmWorkspace | None = None

    def forward(self, maps: np.ndarray) -> np.ndarray:
        """Half spectra of real maps (a new complex64 array)."""
        return to_spectrum(maps)

    def workspace(self) -> admm_kernels.AdmmWorkspace:
        """The ADMM training's buffers for spectra of this shape (made on first use)."""
        if self._workspace is None:
            self._workspace = admm_kernels.AdmmWorkspace(
                self._spectrum_shape, grid_size=self.grid_size
            )
        return self._workspace

    def project_input(self, gain: np.ndarray) -> np.ndarray:
        """F(gain * F^-1(`h_step_input`)) (eq. 12's projection), a new complex64 array.

        The 2-D transforms are taken one axis at a time, as `irfft2` and `rfft2` take them
        (the grid rows, then the half columns, and back), and the transforms along the columns
        only on the band of rows where the gain varies (the target region's): on a row of one
        gain value c the round trip F(c F^-1(row)) is c times the row (without the imaginary
        parts at the zero and Nyquist column frequencies, which the real inverse ignores).
        ~40 % less work than the full transforms on the trackers' windows (one band of a
        fifth of the rows); the same values to rounding (tests/test_backend.py).
        """
        cols = self.grid_size[1]
        # The input is rewritten by the next g-step: pocketfft may work in it (no copy).
        spectrum = scipy.fft.ifft(self.h_step_input, axis=-2, workers=1, overwrite_x=True)
        first, stop = _varying_rows(gain)
        band = scipy.fft.irfft(spectrum[:, first:stop], n=cols, axis=-1, workers=1)
        band *= gain[first:stop]
        # Every row as a row of one gain value; the band's rows are then replaced.
        spectrum *= gain[:, :1]
        spectrum[..., 0].imag = 0.0
        if cols % 2 == 0:
            spectrum[..., cols // 2].imag = 0.0
        spectrum[:, first:stop] = scipy.fft.rfft(band, axis=-1, workers=1)
        return scipy.fft.fft(spectrum, axis=-2, workers=1)


def _varying_rows(gain: np.ndarray) -> tuple[int, int]:
    """(first, stop) of the rows holding every row of `gain` that is not one value throughout
    ((0, 0) when none is)."""
    varying = np.flatnonzero((gain != gain[:, :1]).any(axis=1))
    if varying.size == 0:
        return 0, 0
    return int(varying[0]), int(varying[-1]) + 1


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


def _h_step_gain(spatial_window: np.ndarray, gamma: float, lambda_spatial: float) -> np.ndarray:
    """The h-step's per-cell gain T / (lambda u^2 + gamma T), T = the number of cells (eq. 12)."""
    num_cells = spatial_window.shape[0] * spatial_window.shape[1]
    gain = num_cells / (lambda_spatial * spatial_window**2 + gamma * num_cells)
    return gain.astype(np.float32, copy=False)


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
        gain = _h_step_gain(spatial_window, gamma, settings.lambda_spatial)
        h_f = transform.project_input(gain)
        if theta_of_filter is not None:
            new_theta = theta_of_filter(g_f, iteration)
            if new_theta is not None:
                theta = float(new_theta)
        multiplier_update = (g_f, gamma, work.multipliers[iteration % 2])
        gamma = next_gamma(gamma, settings)
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


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
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


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _half_rolled(values, out):
    """out = np.roll(values, (rows // 2, cols // 2), axis=(0, 1)), cast to out's type."""
    rows, cols = values.shape
    shift_r, shift_c = rows // 2, cols // 2
    for r in range(rows):
        source = values[r - shift_r if r >= shift_r else r - shift_r + rows]
        for c in range(cols):
            out[r, c] = source[c - shift_c if c >= shift_c else c - shift_c + cols]


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
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
    response_f = scipy.fft.fft2(response, workers=1).astype(np.complex128)
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
