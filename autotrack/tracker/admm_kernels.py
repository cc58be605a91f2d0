"""Compiled steps of the ADMM loop (dcf.train_filter): the g-step's per-frequency closed form
(`g_step_kernel`, bit for bit the complex arithmetic it spells out) and element-wise steps,
bit for bit numpy's.

Each kernel fuses what numpy computed as several whole-array operations with temporaries into
one pass, following numpy's operation order and precision exactly: float32 / complex64
arithmetic, one rounding per numpy operation, sums over the channel axis taken channel after
channel (as numpy's reduction over the first axis of a C-contiguous array does), and no
fastmath (no contraction into fused multiply-adds, no reassociation). A product of two complex
numbers is numpy's on x86-64 CPUs with FMA3 (its AVX2 loops): re = fma(a.re, b.re, -(a.im b.im)),
im = fma(a.re, b.im, a.im b.re), with explicit fused multiply-adds (`complex_product`), so a
kernel takes it the same way on every machine (numpy's own product differs only where numpy
has no fused loop). tests/test_admm_kernels.py compares every kernel with the numpy expression
it replaces on features of real sequences.

Arrays are (channels, rows, half columns) complex64 spectra or (channels, rows, cols) float32
maps, C-contiguous.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import intrinsic


@intrinsic
def _fused_multiply_add(typingctx, a, b, c):
    """a * b + c rounded once (llvm.fma: the FMA3 instruction, or libm's fmaf without it)."""
    if not (a == types.float32 and b == types.float32 and c == types.float32):
        return None

    def codegen(context, builder, signature, args):
        return builder.fma(*args)

    return types.float32(types.float32, types.float32, types.float32), codegen


@njit(cache=True, nogil=True, fastmath=False, inline="always")
def complex_product(a_re, a_im, b_re, b_im):
    """(re, im) of (a_re + i a_im)(b_re + i b_im), float32 parts, as numpy's AVX2 loops take a
    complex64 product: with fused multiply-adds."""
    return (
        _fused_multiply_add(a_re, b_re, -(a_im * b_im)),
        _fused_multiply_add(a_re, b_im, a_im * b_re),
    )


@njit(cache=True, nogil=True, fastmath=False)
def shifted_spectrum(zf, phase, out):
    """out = zf * phase[None]: every channel's spectrum times one phase ramp; numpy: the same
    product, broadcast. Flat (channels, frequencies) and (frequencies,) views."""
    channels, frequencies = zf.shape
    for k in range(channels):
        source, target = zf[k], out[k]
        for j in range(frequencies):
            z, p = source[j], phase[j]
            re, im = complex_product(z.real, z.imag, p.real, p.imag)
            target[j] = complex(re, im)


@njit(cache=True, nogil=True, fastmath=False)
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
        re, im = complex_product(x.real, -x.imag, g.real, g.imag)
        s_gx[j] = complex(re, im)
    for k in range(1, channels):
        x_k, g_k = xf[k], g_prev[k]
        for j in range(frequencies):
            x, g = x_k[j], g_k[j]
            s_xx[j] += x.real * x.real + x.imag * x.imag
            re, im = complex_product(x.real, -x.imag, g.real, g.imag)
            total = s_gx[j]
            s_gx[j] = complex(total.real + re, total.imag + im)


NO_SPECTRA = np.zeros((0, 0), np.complex64)
"""`g_step_kernel`'s stand-in for a step it does not take (an out array with no channels, so nothing
is ever written to it; writeable, as the kernel's one signature takes it)."""


@njit(cache=True, nogil=True, fastmath=False)
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
    neighbouring steps when asked: `dcf.solve_g_step`, which documents the arguments."""
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


def scaled_sum(g_f: np.ndarray, l_f: np.ndarray, gamma: np.float32, out: np.ndarray) -> None:
    """out = gamma (g + l), the h-step's right-hand side (eq. 12); numpy:
    np.float32(gamma) * (g_f + l_f)."""
    _scaled_sum_kernel(_parts(g_f), _parts(l_f), gamma, _parts(out))


@njit(cache=True, nogil=True, fastmath=False)
def _scaled_sum_kernel(g_parts, l_parts, gamma, out):
    channels, rows, parts = g_parts.shape
    for k in range(channels):
        for r in range(rows):
            for p in range(parts):
                out[k, r, p] = gamma * (g_parts[k, r, p] + l_parts[k, r, p])


@njit(cache=True, nogil=True, fastmath=False)
def h_step_gain(window, lambda_spatial, gamma, num_cells, out):
    """out = T / (lambda u^2 + gamma T), the h-step's per-cell gain (eq. 12), T = num_cells;
    numpy: (T / (lambda * u**2 + gamma * T)).astype(np.float32) on a float32 window, where the
    Python scalars act as float32 (lambda, T) and gamma * T is taken in float64 first."""
    cells = np.float32(num_cells)
    lam = np.float32(lambda_spatial)
    penalty = np.float32(gamma * num_cells)
    rows, cols = window.shape
    for r in range(rows):
        for c in range(cols):
            u = window[r, c]
            out[r, c] = cells / (lam * (u * u) + penalty)


@njit(cache=True, nogil=True, fastmath=False)
def apply_gain(maps, scale, gain, out):
    """out = (maps * scale) * gain[None]: the inverse transform's 1 / N scaling, which pyFFTW's
    call would take in a pass of its own (a float32 product, `fft_plans.inverse_unscaled`),
    then the h-step's per-cell gain (eq. 12); numpy: h *= gain after the scaled inverse."""
    channels, rows, cols = maps.shape
    for k in range(channels):
        for r in range(rows):
            for c in range(cols):
                out[k, r, c] = (maps[k, r, c] * scale) * gain[r, c]


def _parts(spectrum: np.ndarray) -> np.ndarray:
    """A complex64 (channels, rows, cols) spectrum as float32 (channels, rows, 2 cols): the real
    and imaginary parts side by side, a view. Sums, differences and products by a real scalar
    act on each part alone, so a loop over the parts gives the complex loop's values bit for
    bit, in plain float32 loops the compiler vectorises (2.4x faster at 42 x 50 x 26)."""
    return spectrum.view(np.float32)


class AdmmWorkspace:
    """Buffers of one tracker's ADMM training, reused frame after frame (a tracker trains on one
    thread at a time): all-zero spectra standing for the first iteration's h and multiplier
    (never written), two multiplier buffers (each update reads one and writes the other), the
    per-frequency sums sum_k |x_k|^2 and sum_k conj(x_k) g_prev_k, and the h-step's gain."""

    def __init__(self, spectrum_shape: tuple[int, int, int], grid_size: tuple[int, int]) -> None:
        self.zeros = np.zeros(spectrum_shape, np.complex64)
        self.multipliers = (
            np.empty(spectrum_shape, np.complex64),
            np.empty(spectrum_shape, np.complex64),
        )
        self.s_xx = np.empty(spectrum_shape[1:], np.float32)
        self.s_gx = np.empty(spectrum_shape[1:], np.complex64)
        self.gain = np.empty(grid_size, np.float32)
