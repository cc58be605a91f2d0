"""Compiled steps of the fast backend's ADMM training (`fast_dcf.train_filter`): the g-step's
per-frequency closed form (`g_step_kernel`, the reference `dcf.g_step` with the neighbouring
steps in the same passes) and the per-frame sums it takes.

float32 / complex64 arithmetic, no fastmath (no reassociation, no fused multiply-adds), so a
kernel gives the same bits on every run of one machine. Arrays are (channels, frequencies)
flat views of the (channels, rows, half columns) spectra, C-contiguous.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def training_sums(xf, g_prev, s_xx, s_gx):
    """The g-step's per-frequency terms constant within a frame, in one pass over the channels:
    s_xx = sum_k |x_k|^2 (float32) and s_gx = sum_k conj(x_k) g_prev_k; numpy:
    np.sum(xf.real**2 + xf.imag**2, axis=0) and np.sum(np.conj(xf) * g_prev, axis=0), whose
    reductions start from the first channel's values. Flat (channels, frequencies) and
    (frequencies,) views."""
    channels, frequencies = xf.shape
    x_0, g_0 = xf[0], g_prev[0]
    for j in range(frequencies):
        x, g = x_0[j], g_0[j]
        s_xx[j] = x.real * x.real + x.imag * x.imag
        s_gx[j] = complex(x.real * g.real + x.imag * g.imag, x.real * g.imag - x.imag * g.real)
    for k in range(1, channels):
        x_k, g_k = xf[k], g_prev[k]
        for j in range(frequencies):
            x, g = x_k[j], g_k[j]
            s_xx[j] += x.real * x.real + x.imag * x.imag
            re = x.real * g.real + x.imag * g.imag  # conj(x) g
            im = x.real * g.imag - x.imag * g.real
            total = s_gx[j]
            s_gx[j] = complex(total.real + re, total.imag + im)


NO_SPECTRA = np.zeros((0, 0), np.complex64)
"""`g_step_kernel`'s stand-in for a step it does not take (an out array with no channels, so nothing
is ever written to it; writeable, as the kernel's one signature takes it)."""


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def g_step_kernel(
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
    zero_start,
    g_out,
    g_last,
    multiplier_gamma,
    l_out,
    sum_gamma,
    sum_out,
):
    """The g-step (eqs. 10-11) per frequency, on (channels, frequencies) spectra, with the
    neighbouring steps when asked: `fast_dcf.solve_g_step`, which documents the arguments."""
    # Spectra come in as (channels, frequencies) and per-frequency terms as (frequencies,):
    # flat views of the (rows, half columns) grid, so each loop over a channel is one run of
    # ~1,300 frequencies the compiler vectorises once, not 50 runs of 26 each re-checking their
    # arrays for overlap (2.4x faster at 42 x 50 x 26, the same operations). Loops run
    # channel-outermost so every array is read contiguously. Complex products are spelt out on
    # real and imaginary parts in numba's own order (re = ac - bd, im = ad + bc); a real factor
    # multiplies both parts directly and the division is by a real number, which gives the same
    # values as the complex arithmetic with a zero imaginary part at half the work.
    # `zero_start`: h and l are all zero (the first iteration), so their channel sums are +0
    # for finite x, the value the skipped loop would produce.
    # Two steps of the ADMM loop ride along (each is skipped for an empty out array): with
    # `l_out`, the previous iteration's multiplier update l += gamma' (g' - h) (eq. 14, g' =
    # `g_last`, gamma' = `multiplier_gamma`) is taken first, into `l_out`, and the g-step uses
    # it as its l; with `sum_out`, the h-step's input sum_gamma (g + l) (eq. 12) is written as g
    # is. Both in float32 on each part, as the separate kernels took them, so the same bits.
    channels, frequencies = xf.shape
    update_multiplier = l_out.shape[0] > 0
    write_sum = sum_out.shape[0] > 0
    scale = np.float32(1.0 / (gamma + theta))
    t_scale = np.float32(scale / num_cells)
    gamma_scale = np.float32(gamma * scale)
    theta_scale = np.float32(theta * scale)
    cells_penalty = np.float32(num_cells * (gamma + theta))
    s_hx_re = np.zeros(frequencies, np.float32)
    s_hx_im = np.zeros(frequencies, np.float32)
    s_lx_re = np.zeros(frequencies, np.float32)
    s_lx_im = np.zeros(frequencies, np.float32)
    if update_multiplier:
        for k in range(channels):
            x_k, h_k, l_k, q_k, m_k = xf[k], h_f[k], l_f[k], g_last[k], l_out[k]
            for j in range(frequencies):
                x, h, before, q = x_k[j], h_k[j], l_k[j], q_k[j]
                m_re = before.real + multiplier_gamma * (q.real - h.real)
                m_im = before.imag + multiplier_gamma * (q.imag - h.imag)
                m_k[j] = complex(m_re, m_im)
                # conj(x) h and conj(x) l
                s_hx_re[j] += x.real * h.real + x.imag * h.imag
                s_hx_im[j] += x.real * h.imag - x.imag * h.real
                s_lx_re[j] += x.real * m_re + x.imag * m_im
                s_lx_im[j] += x.real * m_im - x.imag * m_re
        l_f = l_out
    else:
        for k in range(0 if zero_start else channels):
            x_k, h_k, l_k = xf[k], h_f[k], l_f[k]
            for j in range(frequencies):
                x, h, m = x_k[j], h_k[j], l_k[j]
                # conj(x) h and conj(x) l
                s_hx_re[j] += x.real * h.real + x.imag * h.imag
                s_hx_im[j] += x.real * h.imag - x.imag * h.real
                s_lx_re[j] += x.real * m.real + x.imag * m.imag
                s_lx_im[j] += x.real * m.imag - x.imag * m.real
    # x^H rho / ((gamma + theta) B), with B = x^H x + T (gamma + theta)
    proj_re = np.empty(frequencies, np.float32)
    proj_im = np.empty(frequencies, np.float32)
    label_re = np.empty(frequencies, np.float32)  # y / ((gamma + theta) T)
    label_im = np.empty(frequencies, np.float32)
    for j in range(frequencies):
        label_gain = t_scale * s_xx[j]
        y, gx = yf[j], s_gx_prev[j]
        denominator = s_xx[j] + cells_penalty
        proj_re[j] = (
            label_gain * y.real
            + theta_scale * gx.real
            - scale * s_lx_re[j]
            + gamma_scale * s_hx_re[j]
        ) / denominator
        proj_im[j] = (
            label_gain * y.imag
            + theta_scale * gx.imag
            - scale * s_lx_im[j]
            + gamma_scale * s_hx_im[j]
        ) / denominator
        label_re[j] = t_scale * y.real
        label_im[j] = t_scale * y.imag
    for k in range(channels):
        x_k, l_k, h_k, p_k, out_k = xf[k], l_f[k], h_f[k], g_prev[k], g_out[k]
        for j in range(frequencies):
            x, m, h, p = x_k[j], l_k[j], h_k[j], p_k[j]
            y_re, y_im = label_re[j], label_im[j]
            pr, pi = proj_re[j], proj_im[j]
            g_re = (
                (y_re * x.real - y_im * x.imag)
                - scale * m.real
                + gamma_scale * h.real
                + theta_scale * p.real
                - (x.real * pr - x.imag * pi)
            )
            g_im = (
                (y_re * x.imag + y_im * x.real)
                - scale * m.imag
                + gamma_scale * h.imag
                + theta_scale * p.imag
                - (x.real * pi + x.imag * pr)
            )
            out_k[j] = complex(g_re, g_im)
            if write_sum:
                sum_out[k, j] = complex(sum_gamma * (g_re + m.real), sum_gamma * (g_im + m.imag))


class AdmmWorkspace:
    """Buffers of one tracker's ADMM training, reused frame after frame (a tracker trains on one
    thread at a time): all-zero spectra standing for the first iteration's h and multiplier
    (never written), two multiplier buffers (each update reads one and writes the other), the
    per-frequency sums sum_k |x_k|^2 and sum_k conj(x_k) g_prev_k."""

    def __init__(self, spectrum_shape: tuple[int, int, int], grid_size: tuple[int, int]) -> None:
        self.zeros = np.zeros(spectrum_shape, np.complex64)
        self.multipliers = (
            np.empty(spectrum_shape, np.complex64),
            np.empty(spectrum_shape, np.complex64),
        )
        self.s_xx = np.empty(spectrum_shape[1:], np.float32)
        self.s_gx = np.empty(spectrum_shape[1:], np.complex64)
