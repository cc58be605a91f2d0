"""The FFTs of scipy.fft, called on scipy's pocketfft binding directly (one thread).

Each function here makes the call `scipy.fft`'s pocketfft backend makes for the same arguments
(the same routine, normalisation and thread count), so its results are scipy.fft's bit for bit
(tests/test_pocketfft.py checks every call form the tracker uses). What it leaves out is the
import: the binding is loaded from its file by `scipy_binaries.load_compiled`, without
scipy.fft's Python layer (0.27-0.29 s of a fresh process's start-up, docs/benchmarks.md,
round 16), and without the per-call argument handling and backend dispatch of scipy.fft.

Forward transforms are unnormalised, inverse ones divide by the number of points (scipy's
default "backward" normalisation).
"""

from __future__ import annotations

import numpy as np

from autotrack.scipy_binaries import load_compiled

_binding = load_compiled("scipy.fft._pocketfft.pypocketfft")

_FORWARD_NORM = 0  # pocketfft's inorm: no scaling
_INVERSE_NORM = 2  # pocketfft's inorm: divide by the number of points
_THREADS = 1
_GRID_AXES = (-2, -1)


def _floating(values: np.ndarray) -> np.ndarray:
    """Values as scipy.fft passes them on: float16 to float32, integers to float64, native
    byte order and aligned (a copy only when needed)."""
    values = np.asarray(values)
    if values.dtype == np.float16:
        return values.astype(np.float32)
    if values.dtype.kind not in "fc":
        return values.astype(np.float64)
    if values.dtype.byteorder not in "=|" or not values.flags.aligned:
        return np.array(values, dtype=values.dtype.newbyteorder("="), copy=True)
    return values


def rfft2(values: np.ndarray, grid_size: tuple[int, int] | None = None) -> np.ndarray:
    """Half spectrum over the last two axes of real values: `scipy.fft.rfft2(values,
    s=grid_size, workers=1)`; the values are zero-padded to `grid_size` when it is given."""
    values = _floating(values)
    if values.dtype.kind == "c":
        raise TypeError("rfft2 needs real values")
    if grid_size is not None and tuple(values.shape[-2:]) != tuple(grid_size):
        rows, cols = grid_size
        if values.shape[-2] > rows or values.shape[-1] > cols:
            raise ValueError(f"values of shape {values.shape} do not fit a {rows} x {cols} grid")
        padded = np.zeros((*values.shape[:-2], rows, cols), values.dtype)
        padded[..., : values.shape[-2], : values.shape[-1]] = values
        values = padded
    return _binding.r2c(values, _GRID_AXES, True, _FORWARD_NORM, None, _THREADS)


def irfft2(spectrum: np.ndarray, grid_size: tuple[int, int]) -> np.ndarray:
    """Real values on a rows x cols grid from their half spectrum over the last two axes:
    `scipy.fft.irfft2(spectrum, s=grid_size, workers=1)` for a spectrum of the matching
    shape (rows, cols // 2 + 1)."""
    spectrum = _floating(spectrum)
    rows, cols = grid_size
    if tuple(spectrum.shape[-2:]) != (rows, cols // 2 + 1):
        raise ValueError(
            f"a half spectrum of a {rows} x {cols} grid has shape ({rows}, {cols // 2 + 1}) "
            f"in its last two axes, not {tuple(spectrum.shape[-2:])}"
        )
    if spectrum.dtype.kind != "c":
        spectrum = spectrum + 0j
    return _binding.c2r(spectrum, _GRID_AXES, cols, False, _INVERSE_NORM, None, _THREADS)


def fft2(values: np.ndarray) -> np.ndarray:
    """Full spectrum over the last two axes: `scipy.fft.fft2(values, workers=1)`."""
    return _binding.c2c(_floating(values), _GRID_AXES, True, _FORWARD_NORM, None, _THREADS)


def rfft(values: np.ndarray, axis: int = -1) -> np.ndarray:
    """Half spectrum of real values along one axis: `scipy.fft.rfft(values, axis=axis,
    workers=1)`."""
    values = _floating(values)
    if values.dtype.kind == "c":
        raise TypeError("rfft needs real values")
    return _binding.r2c(values, (axis,), True, _FORWARD_NORM, None, _THREADS)


def fft(values: np.ndarray, axis: int = -1) -> np.ndarray:
    """Spectrum along one axis: `scipy.fft.fft(values, axis=axis, workers=1)`."""
    return _binding.c2c(_floating(values), (axis,), True, _FORWARD_NORM, None, _THREADS)


def ifft(spectrum: np.ndarray, axis: int = -1) -> np.ndarray:
    """Inverse transform along one axis: `scipy.fft.ifft(spectrum, axis=axis, workers=1)`."""
    return _binding.c2c(_floating(spectrum), (axis,), False, _INVERSE_NORM, None, _THREADS)
