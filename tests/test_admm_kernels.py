"""The compiled ADMM steps give numpy's results bit for bit on features of real sequences."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from autotrack import AutoTrack, preset
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.io.frames import read_image
from autotrack.tracker import admm_kernels, dcf, regularization
from tests.conftest import COLOUR_TABLE, needs_colour_table, shared_sequence_dir


def _training_inputs(monkeypatch, dataset: str, name: str, frames: int = 6):
    """(xf, filter before the frame, spatial window, transform) of every training of a run."""
    sequence = load_otb_sequence(shared_sequence_dir(dataset, name))[0]
    captured = []
    original = dcf.train_filter

    def recording(xf, yf, g_prev, spatial_window, *args, **kwargs):
        transform = args[2]
        captured.append((xf.copy(), g_prev.copy(), np.array(spatial_window), transform))
        return original(xf, yf, g_prev, spatial_window, *args, **kwargs)

    monkeypatch.setattr(dcf, "train_filter", recording)
    tracker = AutoTrack(preset("autotrack", str(COLOUR_TABLE)))
    tracker.init(read_image(sequence.frame_paths[0]), sequence.init_box)
    for path in sequence.frame_paths[1:frames]:
        tracker.update(read_image(path))
    return captured[1:]  # the first training starts from a zero filter


SEQUENCES = [("DTB70", "Surfing06"), ("UAV123_10fps", "boat5"), ("OTB", "Crossing")]


def _numpy_shift(xf, shift_rows, shift_cols):
    """shift_spectrum as numpy computed it before its kernel: the broadcast complex64 product."""
    rows, half = xf.shape[1], xf.shape[2]
    ky = dcf.centred_frequencies(rows)
    kx = np.arange(half, dtype=np.float64)
    phase_rows = np.exp(1j * (2.0 * np.pi * shift_rows / rows) * ky).astype(np.complex64)
    phase_cols = np.exp(1j * (2.0 * np.pi * shift_cols / rows) * kx).astype(np.complex64)
    return xf * (phase_rows[:, None] * phase_cols[None, :])


def _numpy_fuses_complex_products() -> bool:
    """Whether numpy multiplies complex64 arrays with fused multiply-adds on this machine, as
    `admm_kernels.complex_product` always does (numpy's AVX2 loops on x86-64 CPUs with FMA3):
    where it does not, the kernels' products differ from numpy's in the last bit."""
    rng = np.random.default_rng(0)
    a, b = (rng.standard_normal((2, 4099, 2)) @ np.array([1, 1j])).astype(np.complex64)
    fused = np.empty((1, a.size), np.complex64)
    admm_kernels.shifted_spectrum(a[None], b, fused)
    return bool(np.array_equal(fused[0], a * b))


NUMPY_FUSES = _numpy_fuses_complex_products()
needs_fused_numpy = pytest.mark.skipif(
    not NUMPY_FUSES, reason="numpy's complex products are not fused on this CPU"
)


def _assert_products_equal(got: np.ndarray, expected: np.ndarray) -> None:
    """Bit for bit where numpy fuses its complex products; else within float32 rounding."""
    if NUMPY_FUSES:
        np.testing.assert_array_equal(got.view(np.uint64), expected.view(np.uint64))
    else:
        np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6 * np.abs(expected).max())


def test_complex_product_is_fused():
    """The kernels' complex product rounds a * b + c once: where the unfused product (two
    roundings) loses the answer, it keeps it."""
    e = 2.0**-13  # re = (1 + e)(1 - e) - 1 * 1 = -e^2, but 1 - e^2 rounds to 1 in float32
    a = np.array([1 + e + 1j], np.complex64)
    b = np.array([1 - e + 1j], np.complex64)
    out = np.empty((1, 1), np.complex64)
    admm_kernels.shifted_spectrum(a[None], b, out)
    assert out[0, 0].real == np.float32(-(e**2))
    assert (a.real * b.real - a.imag * b.imag)[0] == np.float32(0.0)


@needs_colour_table
@pytest.mark.parametrize(("dataset", "name"), SEQUENCES)
def test_admm_kernels_equal_numpy_bit_for_bit(monkeypatch, dataset, name):
    for xf, g_prev, _, _ in _training_inputs(monkeypatch, dataset, name):
        energy = np.empty(xf.shape[1:], np.float32)
        s_gx = np.empty(xf.shape[1:], np.complex64)
        flat = xf.reshape(len(xf), -1)
        admm_kernels.training_sums(
            flat, g_prev.reshape(len(xf), -1), energy.reshape(-1), s_gx.reshape(-1)
        )
        np.testing.assert_array_equal(energy, np.sum(xf.real**2 + xf.imag**2, axis=0))
        _assert_products_equal(s_gx, np.sum(np.conj(xf) * g_prev, axis=0))
        for shift in ((0.0, 0.0), (1.37, -2.6), (-7.25, 11.0)):
            got = dcf.shift_spectrum(xf, *shift, (xf.shape[1], xf.shape[1]))
            expected = dcf.shift_spectrum(xf.astype(np.complex128), *shift, (xf.shape[1],) * 2)
            np.testing.assert_allclose(got, expected, rtol=0, atol=1e-5 * np.abs(xf).max())
            _assert_products_equal(got, _numpy_shift(xf, *shift))

        multiplier = (xf - g_prev) * np.float32(0.37)
        for gamma in (1.0, 10.0, 0.7312):
            expected = np.float32(gamma) * (g_prev + multiplier)
            got = np.empty_like(expected)
            admm_kernels.scaled_sum(g_prev, multiplier, np.float32(gamma), got)
            np.testing.assert_array_equal(got, expected)


def _train_filter_before_the_workspace(
    xf, yf, g_prev, window, theta_start, settings, transform, rule
):
    """train_filter as it was before its buffers were kept across frames: new zero spectra for
    h and the multiplier, numpy's channel sums, the multiplier updated in numpy."""
    cells = transform.grid_size[0] * transform.grid_size[1]
    h_f, l_f = np.zeros_like(xf), np.zeros_like(xf)
    s_xx = np.sum(xf.real**2 + xf.imag**2, axis=0)
    s_gx = np.sum(np.conj(xf) * g_prev, axis=0)
    gamma, theta = settings.gamma_init, theta_start
    for iteration in range(1, settings.iterations + 1):
        args = (xf, yf, h_f, l_f, g_prev, s_xx, s_gx, gamma, theta, cells, iteration == 1)
        g_f = dcf.solve_g_step(*args)
        if iteration == settings.iterations:
            break
        h_f = dcf.solve_h_step(g_f, l_f, window, gamma, settings.lambda_spatial, transform)
        theta = rule(g_f, iteration)
        l_f += np.float32(gamma) * (g_f - h_f)
        gamma = min(settings.gamma_step * gamma, settings.gamma_max)
    return g_f, theta


@needs_colour_table
@needs_fused_numpy
@pytest.mark.parametrize(("dataset", "name"), SEQUENCES)
def test_training_with_kept_buffers_equals_fresh_buffers_bit_for_bit(monkeypatch, dataset, name):
    """The workspace's buffers, reused frame after frame (the tracker's own, left as its last
    training left them), give the filters of fresh zero buffers and numpy's sums."""
    settings = dcf.AdmmSettings(4, 1.0, 1.0, 10.0, 1e4)
    trainings = _training_inputs(monkeypatch, dataset, name, frames=8)
    yf = dcf.to_spectrum(dcf.gaussian_label(trainings[0][3].grid_size, 2.1).astype(np.float32))
    for xf, g_prev, window, transform in trainings:
        for theta_ref in (0.0, 13.0, 5.0):
            rule = regularization.theta_update("release", theta_ref, g_prev, transform.grid_size)
            expected = _train_filter_before_the_workspace(
                xf, yf, g_prev, window, 13.0, settings, transform, rule
            )
            got = dcf.train_filter(xf, yf, g_prev, window, 13.0, settings, transform, rule)
            np.testing.assert_array_equal(got[0].view(np.uint64), expected[0].view(np.uint64))
            assert got[1] == expected[1]


@needs_colour_table
@pytest.mark.parametrize(("dataset", "name"), SEQUENCES[:2])
def test_h_step_equals_the_numpy_h_step_bit_for_bit(monkeypatch, dataset, name):
    """Kernels + FFTW on its own buffers = inverse, numpy gain, forward as numpy computed it."""
    for xf, g_prev, window, transform in _training_inputs(monkeypatch, dataset, name):
        cells = transform.grid_size[0] * transform.grid_size[1]
        multiplier = (xf - g_prev) * np.float32(0.37)
        for gamma in (1.0, 10.0):
            gain = (cells / (0.1 * window**2 + gamma * cells)).astype(np.float32)
            maps = transform.inverse_scratch(np.float32(gamma) * (g_prev + multiplier))
            maps *= gain
            expected = transform.forward(maps)
            got = dcf.solve_h_step(g_prev, multiplier, window, gamma, 0.1, transform)
            np.testing.assert_array_equal(got, expected)


@njit(cache=False, fastmath=False)
def _g_step_in_complex_arithmetic(xf, yf, h_f, l_f, g_prev, s_xx, s_gx, gamma, theta, cells, out):
    """The g-step (eqs. 10-11) as it was written before, in numba's complex arithmetic."""
    channels, rows, cols = xf.shape
    scale = np.float32(1.0 / (gamma + theta))
    t_scale = np.float32(scale / cells)
    gamma_scale = np.float32(gamma * scale)
    theta_scale = np.float32(theta * scale)
    cells_penalty = np.float32(cells * (gamma + theta))
    s_hx = np.zeros((rows, cols), np.complex64)
    s_lx = np.zeros((rows, cols), np.complex64)
    for k in range(channels):
        for r in range(rows):
            for c in range(cols):
                s_hx[r, c] += np.conj(xf[k, r, c]) * h_f[k, r, c]
                s_lx[r, c] += np.conj(xf[k, r, c]) * l_f[k, r, c]
    projection = np.empty((rows, cols), np.complex64)
    for r in range(rows):
        for c in range(cols):
            projection[r, c] = (
                t_scale * s_xx[r, c] * yf[r, c]
                + theta_scale * s_gx[r, c]
                - scale * s_lx[r, c]
                + gamma_scale * s_hx[r, c]
            ) / (s_xx[r, c] + cells_penalty)
    for k in range(channels):
        for r in range(rows):
            for c in range(cols):
                x = xf[k, r, c]
                out[k, r, c] = (
                    t_scale * yf[r, c] * x
                    - scale * l_f[k, r, c]
                    + gamma_scale * h_f[k, r, c]
                    + theta_scale * g_prev[k, r, c]
                    - x * projection[r, c]
                )


@needs_colour_table
@pytest.mark.parametrize(("dataset", "name"), SEQUENCES[:2])
def test_g_step_kernel_equals_complex_arithmetic_bit_for_bit(monkeypatch, dataset, name):
    for xf, g_prev, _, transform in _training_inputs(monkeypatch, dataset, name):
        yf = xf[0] * np.complex64(0.5 - 0.25j)
        h_f, l_f = (xf + g_prev) * np.float32(0.5), (xf - g_prev) * np.float32(0.37)
        s_xx = np.sum(xf.real**2 + xf.imag**2, axis=0)
        s_gx = np.sum(np.conj(xf) * g_prev, axis=0)
        cells = transform.grid_size[0] * transform.grid_size[1]
        for gamma, theta in ((1.0, 0.0), (10.0, 12.5), (0.7312, 3.0)):
            expected = np.empty_like(xf)
            args = (xf, yf, h_f, l_f, g_prev, s_xx, s_gx, gamma, theta, cells)
            _g_step_in_complex_arithmetic(*args, expected)
            np.testing.assert_array_equal(dcf.solve_g_step(*args), expected)


@needs_colour_table
@pytest.mark.parametrize(("dataset", "name"), SEQUENCES[:2])
def test_g_step_zero_start_equals_the_full_sums_bit_for_bit(monkeypatch, dataset, name):
    """ADMM's first g-step skips the channel sums of h and l, which are all zero there."""
    for xf, g_prev, _, transform in _training_inputs(monkeypatch, dataset, name):
        yf = xf[0] * np.complex64(0.5 - 0.25j)
        zeros = np.zeros_like(xf)
        s_xx = np.sum(xf.real**2 + xf.imag**2, axis=0)
        s_gx = np.sum(np.conj(xf) * g_prev, axis=0)
        cells = transform.grid_size[0] * transform.grid_size[1]
        for gamma, theta in ((1.0, 0.0), (1.0, 12.5), (0.7312, 3.0)):
            args = (xf, yf, zeros, zeros, g_prev, s_xx, s_gx, gamma, theta, cells)
            full = dcf.solve_g_step(*args, zero_start=False)
            skipped = dcf.solve_g_step(*args, zero_start=True)
            np.testing.assert_array_equal(skipped.view(np.uint64), full.view(np.uint64))


def _newton_peak_in_numpy(response, iterations):
    """The Newton peak as it was written before its kernel (the release's matrix products)."""
    rows, cols = response.shape
    response_f = np.fft.fft2(response).astype(np.complex64)
    peak_row, peak_col = divmod(int(np.argmax(response)), cols)
    init_score = float(response[peak_row, peak_col])
    trans_row = (peak_row + (rows - 1) // 2) % rows - (rows - 1) // 2
    trans_col = (peak_col + (cols - 1) // 2) % cols - (cols - 1) // 2
    pos_y, pos_x = 2.0 * np.pi * trans_row / rows, 2.0 * np.pi * trans_col / cols
    init_y, init_x = pos_y, pos_x
    ky, kx = dcf.centred_frequencies(rows), dcf.centred_frequencies(cols)
    exp_iky, exp_ikx = np.exp(1j * ky * pos_y), np.exp(1j * kx * pos_x)
    for _ in range(iterations):
        y_resp, resp_x = exp_iky @ response_f, response_f @ exp_ikx
        grad_y = -(ky * exp_iky @ resp_x).imag
        grad_x = -(y_resp @ (kx * exp_ikx)).imag
        ival = 1j * (exp_iky @ resp_x)
        h_yy = (-(ky**2 * exp_iky) @ resp_x + ival).real
        h_xx = (-y_resp @ (kx**2 * exp_ikx) + ival).real
        h_xy = (-(ky * exp_iky @ (response_f @ (kx * exp_ikx)))).real
        det = h_yy * h_xx - h_xy * h_xy
        pos_y = pos_y - (h_xx * grad_y - h_xy * grad_x) / det
        pos_x = pos_x - (h_yy * grad_x - h_xy * grad_y) / det
        exp_iky, exp_ikx = np.exp(1j * ky * pos_y), np.exp(1j * kx * pos_x)
    score = float(np.real(exp_iky @ response_f @ exp_ikx)) / (rows * cols)
    if score < init_score:
        pos_y, pos_x, score = init_y, init_x, init_score
    wrap = 2.0 * np.pi
    return (
        (np.mod(pos_y + np.pi, wrap) - np.pi) / wrap * rows,
        (np.mod(pos_x + np.pi, wrap) - np.pi) / wrap * cols,
        score,
    )


@needs_colour_table
@pytest.mark.parametrize(("dataset", "name"), SEQUENCES)
def test_newton_kernel_equals_the_numpy_newton_peak(monkeypatch, dataset, name):
    """The compiled Newton iterations give the matrix-product version's peak on real responses
    (to float rounding: the sums are taken in another order)."""
    responses = []
    original = dcf.detection_response

    def recording(*args):
        responses.append(original(*args))
        return responses[-1]

    monkeypatch.setattr(dcf, "detection_response", recording)
    _training_inputs(monkeypatch, dataset, name, frames=12)
    assert len(responses) >= 10
    for response in responses:
        got = dcf.newton_peak(response, 5)
        expected = _newton_peak_in_numpy(response, 5)
        np.testing.assert_allclose(got[:2], expected[:2], rtol=0, atol=1e-6)
        assert got[2] == pytest.approx(expected[2], rel=1e-6)


@needs_colour_table
@pytest.mark.parametrize(("dataset", "name"), SEQUENCES)
def test_correlation_kernel_equals_numpy_einsum_bit_for_bit(monkeypatch, dataset, name):
    """Detection's sum_k conj(g_k) z_k (eq. 16) gives np.einsum's spectrum exactly, on filters
    and features of real sequences."""
    trainings = _training_inputs(monkeypatch, dataset, name, frames=8)
    for (xf, g_prev, _, _), (later_xf, _, _, _) in zip(trainings, trainings[1:], strict=False):
        for filter_f, features_f in ((g_prev, xf), (g_prev, later_xf), (xf, g_prev)):
            expected = np.einsum("krc,krc->rc", np.conj(filter_f), features_f)
            got = dcf.correlation_spectrum(filter_f, features_f)
            np.testing.assert_array_equal(got.view(np.uint64), expected.view(np.uint64))
