"""Compiled element-wise steps of the ADMM loop (dcf.train_filter), bit for bit numpy's.

Each kernel fuses what numpy computed as several whole-array operations with temporaries into
one pass, following numpy's operation order and precision exactly: float32 / complex64
arithmetic, one rounding per numpy operation, products of complex numbers only by real scalars
(numpy multiplies two complex64 arrays with fused multiply-adds where the CPU has them, which
a kernel could not follow on every machine), sums over the channel axis taken channel after
channel (as numpy's reduction over the first axis of a C-contiguous array does), and no
fastmath (no contraction into fused multiply-adds, no reassociation). tests/test_admm_kernels.py
compares every kernel with the numpy expression it replaces on features of real sequences.

Arrays are (channels, rows, half columns) complex64 spectra or (channels, rows, cols) float32
maps, C-contiguous.

The one exception to "no complex products of two arrays": `training_input` follows numpy's
complex64 product in either form numpy computes it in: with fused multiply-adds (numpy's SIMD
loops on CPUs with FMA: re = fma(a_r, b_r, -(a_i b_i)), im = fma(a_r, b_i, a_i b_r)) or without;
`NUMPY_FUSES_COMPLEX_PRODUCTS`, probed once at import, says which one this machine's numpy uses
(tests/test_admm_kernels.py checks the kernel against numpy on real features).
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core.extending import intrinsic


@njit(cache=True, nogil=True, fastmath=False)
def scaled_sum(g_f, l_f, gamma, out):
    """out = gamma (g + l), the h-step's right-hand side (eq. 12); numpy:
    np.float32(gamma) * (g_f + l_f)."""
    channels, rows, cols = g_f.shape
    for k in range(channels):
        for r in range(rows):
            for c in range(cols):
                total = g_f[k, r, c] + l_f[k, r, c]
                out[k, r, c] = complex(gamma * total.real, gamma * total.imag)


@njit(cache=True, nogil=True, fastmath=False)
def apply_gain(maps, gain, out):
    """out = maps * gain[None]: the h-step's per-cell gain (eq. 12); numpy: h *= gain."""
    channels, rows, cols = maps.shape
    for k in range(channels):
        for r in range(rows):
            for c in range(cols):
                out[k, r, c] = maps[k, r, c] * gain[r, c]


@njit(cache=True, nogil=True, fastmath=False)
def update_multiplier(l_f, g_f, h_f, gamma, out):
    """out = l + gamma (g - h), the multiplier update (eq. 14), in place when `out` is `l_f`;
    numpy: l_f += np.float32(gamma) * (g_f - h_f)."""
    channels, rows, cols = l_f.shape
    for k in range(channels):
        for r in range(rows):
            for c in range(cols):
                step = g_f[k, r, c] - h_f[k, r, c]
                out[k, r, c] = l_f[k, r, c] + complex(gamma * step.real, gamma * step.imag)


@intrinsic
def _fma32(typingctx, a, b, c):
    """a * b + c with a single rounding (LLVM's fma on float32)."""
    signature = types.float32(types.float32, types.float32, types.float32)

    def codegen(context, builder, signature, args):
        f32 = ir.FloatType()
        fma = builder.module.declare_intrinsic(
            "llvm.fma", [f32], ir.FunctionType(f32, [f32, f32, f32])
        )
        return builder.call(fma, args)

    return signature, codegen


@njit(cache=True, nogil=True, fastmath=False, inline="always")
def _product(a_re, a_im, b_re, b_im, fused):
    """numpy's complex64 a * b, in the form `fused` names (see the module's docstring)."""
    if fused:
        return _fma32(a_re, b_re, -(a_im * b_im)), _fma32(a_re, b_im, a_im * b_re)
    return a_re * b_re - a_im * b_im, a_re * b_im + a_im * b_re


def _numpy_fuses_complex_products() -> bool:
    """Whether numpy's complex64 product here is the fused form: False when it equals the plain
    form (each product and sum rounded on its own, computed with numpy's float32 ufuncs) on
    random numbers, where the fused form differs in about a quarter of them."""
    rng = np.random.default_rng(0)
    a, b = (
        (rng.standard_normal(1024) + 1j * rng.standard_normal(1024)).astype(np.complex64)
        for _ in range(2)
    )
    product = a * b
    plain_re = a.real * b.real - a.imag * b.imag
    plain_im = a.real * b.imag + a.imag * b.real
    return not (np.array_equal(product.real, plain_re) and np.array_equal(product.imag, plain_im))


NUMPY_FUSES_COMPLEX_PRODUCTS = _numpy_fuses_complex_products()


@njit(cache=True, nogil=True, fastmath=False)
def training_input(zf, phase, shift, g_prev, fused, xf, energy, s_gx_prev):
    """The training's per-frame inputs in one pass over the detection features `zf`:
    xf = zf * phase[None] when `shift` (the features moved in the Fourier domain; numpy:
    `zf * phase`), else a copy of zf; energy = sum_k |x_k|^2 (numpy:
    `np.sum(xf.real**2 + xf.imag**2, axis=0)`); s_gx_prev =
    sum_k conj(x_k) g_prev_k (numpy: `np.sum(np.conj(xf) * g_prev, axis=0)`); channel sums
    channel after channel, complex products as numpy's (`fused`)."""
    channels, rows, cols = zf.shape
    for k in range(channels):
        for r in range(rows):
            for c in range(cols):
                z, g = zf[k, r, c], g_prev[k, r, c]
                x_re, x_im = z.real, z.imag
                if shift:
                    p = phase[r, c]
                    x_re, x_im = _product(z.real, z.imag, p.real, p.imag, fused)
                xf[k, r, c] = complex(x_re, x_im)
                x_energy = x_re * x_re + x_im * x_im
                s_re, s_im = _product(x_re, -x_im, g.real, g.imag, fused)
                if k == 0:
                    energy[r, c] = x_energy
                    s_gx_prev[r, c] = complex(s_re, s_im)
                else:
                    energy[r, c] += x_energy
                    total = s_gx_prev[r, c]
                    s_gx_prev[r, c] = complex(total.real + s_re, total.imag + s_im)


class AdmmWorkspace:
    """Buffers of one tracker's ADMM training, reused frame after frame (a tracker trains on one
    thread at a time): all-zero spectra standing for the first iteration's h and multiplier
    (never written), the multiplier, the (shifted) training features and their per-frequency
    sums sum_k |x_k|^2 and sum_k conj(x_k) g_prev_k."""

    def __init__(self, spectrum_shape: tuple[int, int, int]) -> None:
        self.zeros = np.zeros(spectrum_shape, np.complex64)
        self.multiplier = np.empty(spectrum_shape, np.complex64)
        self.features = np.empty(spectrum_shape, np.complex64)
        self.s_xx = np.empty(spectrum_shape[1:], np.float32)
        self.s_gx_prev = np.empty(spectrum_shape[1:], np.complex64)


NO_PHASE = np.ones((1, 1), np.complex64)  # `training_input` reads no phase without a shift
