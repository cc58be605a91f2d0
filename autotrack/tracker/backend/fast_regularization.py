"""`regularization.local_variation` (eq. 2) in one compiled pass (the fast backend): both maps
read through their centring shifts instead of rolled copies, the same float32 operations per
element, so the same values bit for bit (tests/test_backend.py)."""

from __future__ import annotations

import numpy as np
from numba import njit

from autotrack.tracker.regularization import centring_shift


def local_variation(
    response: np.ndarray,
    displacement: tuple[float, float],
    previous_response: np.ndarray,
    previous_displacement: tuple[float, float],
) -> np.ndarray:
    """Local response variation Pi = |R_t - R_{t-1}| / |R_{t-1}| of the two maps aligned and
    centred (eq. 2; `regularization.local_variation`), float32; inf/NaN where R_{t-1} is 0."""
    shift = centring_shift(response.shape, displacement)
    previous_shift = centring_shift(previous_response.shape, previous_displacement)
    out = np.empty(response.shape, np.float32)
    _centred_variation(response, previous_response, *shift, *previous_shift, out)
    return out


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _centred_variation(response, previous, shift_r, shift_c, previous_r, previous_c, out):
    """out = |roll(response) - roll(previous)| / |roll(previous)|, each map rolled by its own
    (rows, cols) shift as np.roll rolls (rolled[i] = map[(i - shift) mod n])."""
    rows, cols = response.shape
    for r in range(rows):
        values = response[(r - shift_r) % rows]
        befores = previous[(r - previous_r) % rows]
        for c in range(cols):
            value, before = values[(c - shift_c) % cols], befores[(c - previous_c) % cols]
            out[r, c] = abs(value - before) / abs(before)
