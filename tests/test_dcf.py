"""The filter's maths: g-step, h-step, detection peak, Fourier shifts, regularisation signals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autotrack.tracker import dcf, regularization


def _random_spectra(rng: np.random.Generator, grid=(6, 8), channels=3):
    features = rng.standard_normal((channels, *grid)).astype(np.float32)
    return features, dcf.to_spectrum(features)


def test_g_step_closed_form_equals_direct_per_pixel_solve():
    rng = np.random.default_rng(0)
    grid, channels = (6, 8), 3
    num_cells = grid[0] * grid[1]
    _, xf = _random_spectra(rng, grid, channels)
    _, h_f = _random_spectra(rng, grid, channels)
    _, l_f = _random_spectra(rng, grid, channels)
    _, g_prev = _random_spectra(rng, grid, channels)
    yf = dcf.to_spectrum(dcf.gaussian_label(grid, 1.3).astype(np.float32))
    gamma, theta = 10.0, 13.0
    g_f = dcf.g_step(xf, yf, h_f, l_f, g_prev, gamma, theta, num_cells)

    # Per frequency j: (x x^H / T + (gamma + theta) I) g = y x / T - l + gamma h + theta g_prev.
    for row in range(xf.shape[1]):
        for col in range(xf.shape[2]):
            x = xf[:, row, col].astype(np.complex128)
            system = np.outer(x, np.conj(x)) / num_cells + (gamma + theta) * np.eye(channels)
            rhs = (
                yf[row, col] * x / num_cells
                - l_f[:, row, col]
                + gamma * h_f[:, row, col]
                + theta * g_prev[:, row, col]
            )
            expected = np.linalg.solve(system, rhs)
            np.testing.assert_allclose(g_f[:, row, col], expected, rtol=1e-4, atol=1e-5)


def test_h_step_equals_its_definition_on_the_full_spectrum():
    rng = np.random.default_rng(1)
    grid, channels = (7, 10), 2
    num_cells = grid[0] * grid[1]
    g_space = rng.standard_normal((channels, *grid))
    l_space = rng.standard_normal((channels, *grid))
    window = rng.uniform(0.001, 5.0, size=grid)
    gamma, lam = 100.0, 1.0
    g_half = dcf.to_spectrum(g_space.astype(np.float32))
    l_half = dcf.to_spectrum(l_space.astype(np.float32))
    h_half = dcf.h_step(g_half, l_half, window.astype(np.float32), gamma, lam)

    # Definition (paper eq. 12, release form): h = T / (lambda u^2 + gamma T) * ifft2(gamma (g + l)).
    g_full = np.fft.fft2(g_space)
    l_full = np.fft.fft2(l_space)
    h_space = (num_cells / (lam * window**2 + gamma * num_cells)) * np.fft.ifft2(
        gamma * (g_full + l_full)
    )
    h_full = np.fft.fft2(h_space)
    np.testing.assert_allclose(h_half, h_full[..., : grid[1] // 2 + 1], rtol=1e-4, atol=1e-3)


@pytest.mark.parametrize("shift", [(0.0, 0.0), (2.3, -1.6), (-4.45, 3.7), (0.5, 0.5)])
def test_newton_peak_recovers_a_known_subpixel_shift(shift):
    grid = (50, 46)
    rows = dcf.centred_frequencies(grid[0])[:, None]
    cols = dcf.centred_frequencies(grid[1])[None, :]
    # A smooth periodic peak at (shift): Gaussian spectrum times the shift's phase ramp.
    spectrum = np.exp(-0.5 * ((rows / 6.0) ** 2 + (cols / 6.0) ** 2)) * np.exp(
        -2j * np.pi * (rows * shift[0] / grid[0] + cols * shift[1] / grid[1])
    )
    response = np.real(np.fft.ifft2(spectrum))
    disp_row, disp_col, score = dcf.newton_peak(response, iterations=5)
    assert disp_row == pytest.approx(shift[0], abs=0.02)
    assert disp_col == pytest.approx(shift[1], abs=0.02)
    assert score >= response.max() - 1e-12


def test_shift_spectrum_moves_features_by_whole_cells():
    rng = np.random.default_rng(2)
    grid = (12, 10)
    features = rng.standard_normal((2, *grid)).astype(np.float32)
    shifted = dcf.from_spectrum(dcf.shift_spectrum(dcf.to_spectrum(features), 3, -2, grid), grid)
    # exp(+i k s) reads the signal s cells further on: out[r, c] = in[r + 3, c - 2].
    np.testing.assert_allclose(shifted, np.roll(features, (-3, 2), axis=(1, 2)), atol=1e-5)


def test_label_peaks_at_origin_and_window_matches_release_hann():
    label = dcf.gaussian_label((5, 6), 1.0)
    assert label[0, 0] == pytest.approx(1.0)
    assert label[1, 0] == pytest.approx(label[-1, 0])
    window = dcf.cosine_window((3, 3))
    # MATLAB hann(5) = [0 .5 1 .5 0]; without its ends [.5 1 .5].
    np.testing.assert_allclose(window[1], [0.5, 1.0, 0.5], atol=1e-7)


def test_matlab_round_rounds_halves_away_from_zero():
    np.testing.assert_array_equal(dcf.matlab_round([0.5, 1.5, 2.5, -0.5, -2.5]), [1, 2, 3, -1, -3])


def test_local_variation_is_zero_for_a_translated_identical_response():
    rng = np.random.default_rng(3)
    previous = rng.uniform(0.1, 1.0, size=(10, 10))
    current = np.roll(previous, (2, -3), axis=(0, 1))
    variation = regularization.local_variation(current, (2.4, -2.6), previous, (0.2, 0.1))
    # floor(2.4) = 2, floor(-2.6) = -3: aligning both peaks undoes the motion exactly.
    np.testing.assert_allclose(variation, 0.0, atol=1e-6)
    assert regularization.global_variation(variation) == pytest.approx(0.0, abs=1e-9)


def test_local_variation_matches_hand_computed_values():
    # 2 x 3 maps. The current peak moved by (1.5, -0.5) cells: floor -> (1, -1), so the aligned
    # map is aligned[r, c] = current[(r + 1) % 2, (c - 1) % 3]; the previous one did not move.
    current = np.array([[10.0, 5.0, 4.0], [2.0, 2.0, 2.0]])
    previous = np.array([[1.0, 2.0, -4.0], [8.0, 5.0, 10.0]])
    # aligned = [[2, 2, 2], [4, 10, 5]]; Pi = |aligned - previous| / |previous|:
    #   [[1/1, 0/2, 6/4], [4/8, 5/5, 5/10]] = [[1, 0, 1.5], [0.5, 1, 0.5]],
    # then centred by a circular shift of floor([2, 3] / 2) = (1, 1).
    expected = np.array([[0.5, 0.5, 1.0], [1.5, 1.0, 0.0]])
    variation = regularization.local_variation(current, (1.5, -0.5), previous, (0.0, 0.0))
    assert variation.dtype == np.float32
    np.testing.assert_allclose(variation, expected, rtol=1e-6)


def test_local_variation_aligns_each_map_by_its_own_floored_peak():
    rng = np.random.default_rng(5)
    rows, cols = 7, 8
    current = rng.uniform(-1.0, 1.0, size=(rows, cols))
    previous = rng.uniform(0.2, 1.0, size=(rows, cols)) * rng.choice([-1.0, 1.0], (rows, cols))
    displacement, previous_displacement = (-1.3, 2.7), (0.6, -2.2)
    variation = regularization.local_variation(
        current, displacement, previous, previous_displacement
    )
    # Element by element, from the index formulas: shift by -floor(d), then centre by
    # floor(size / 2) -> Pi_centred[r, c] = Pi[r - 3, c - 4].
    expected = np.empty((rows, cols))
    for r in range(rows):
        for c in range(cols):
            r0, c0 = (r - rows // 2) % rows, (c - cols // 2) % cols
            now = current[(r0 - 2) % rows, (c0 + 2) % cols]  # floor(-1.3) = -2, floor(2.7) = 2
            before = previous[r0 % rows, (c0 - 3) % cols]  # floor(0.6) = 0, floor(-2.2) = -3
            expected[r, c] = abs(now - before) / abs(before)
    np.testing.assert_allclose(variation, expected, rtol=1e-5)


def test_local_variation_of_a_zero_previous_response_is_flagged_not_hidden():
    previous = np.ones((4, 4))
    previous[0, 0] = 0.0
    current = np.ones((4, 4))
    current[0, 1] = 0.0
    previous[0, 1] = 0.0  # 0 / 0
    current[0, 0] = 3.0  # 2 / 0
    variation = regularization.local_variation(current, (0.0, 0.0), previous, (0.0, 0.0))
    # Centred by (2, 2): the two bad entries land at (2, 2) and (2, 3); the rest is exact 0.
    assert variation[2, 2] == np.inf and np.isnan(variation[2, 3])
    finite = np.isfinite(variation)
    assert finite.sum() == 14 and np.all(variation[finite] == 0.0)
    eta = regularization.global_variation(variation)
    assert eta == float("inf") and regularization.is_aberrant(eta, 0.3)


def test_global_variation_uses_the_spectral_norm_and_flags_blow_ups():
    variation = np.diag([3.0, 4.0]).astype(np.float32)
    # Largest singular value 4 (Frobenius would be 5), scaled by 1e-4.
    assert regularization.global_variation(variation) == pytest.approx(4e-4)
    variation[0, 1] = np.inf
    assert regularization.global_variation(variation) == float("inf")
    assert regularization.is_aberrant(float("inf"), 0.3)
    assert regularization.is_aberrant(float("nan"), 0.3)
    assert not regularization.is_aberrant(0.29, 0.3)


def test_global_variation_of_edge_cases():
    assert regularization.global_variation(np.zeros((5, 5), np.float32)) == 0.0
    full = np.full((50, 50), 2.0, np.float32)  # rank one: its singular value is 100
    assert regularization.global_variation(full) == pytest.approx(100.0 * 1e-4)
    for bad in (np.inf, -np.inf, np.nan):
        matrix = np.ones((4, 3))
        matrix[2, 1] = bad
        assert regularization.global_variation(matrix) == math.inf


def test_spectral_norm_is_the_largest_singular_value():
    # The Gram matrix's largest eigenvalue, against LAPACK's SVD: square, tall and wide maps
    # of variation-like (non-negative, wide-ranging) values.
    rng = np.random.default_rng(5)
    for shape in ((50, 50), (50, 31), (23, 50), (1, 9), (9, 1)):
        for _ in range(20):
            matrix = np.abs(rng.standard_normal(shape)) * rng.uniform(1e-3, 1e3)
            expected = np.linalg.norm(matrix, ord=2)
            assert regularization.spectral_norm(matrix) == pytest.approx(expected, rel=1e-14)


def test_multiplier_update_and_gamma_schedule():
    settings = dcf.AdmmSettings(4, 1.0, 1.0, 10.0, 10000.0)
    gammas = [1.0]
    for _ in range(5):
        gammas.append(dcf.next_gamma(gammas[-1], settings))
    assert gammas == [1.0, 10.0, 100.0, 1000.0, 10000.0, 10000.0]  # eq. 15, capped
    l_f, g_f, h_f = np.complex64(1 + 1j), np.complex64(3 - 2j), np.complex64(1 + 1j)
    assert dcf.multiplier_update(l_f, g_f, h_f, 10.0) == np.complex64(21 - 29j)  # eq. 14


def test_centred_response_is_numpys_fftshift_as_float32():
    rng = np.random.default_rng(7)
    for shape in ((50, 50), (37, 44), (1, 1), (2, 3)):
        for dtype in (np.float32, np.float64):
            response = rng.standard_normal(shape).astype(dtype)
            centred = dcf.centred_response(response)
            assert centred.dtype == np.float32
            np.testing.assert_array_equal(centred, np.fft.fftshift(response).astype(np.float32))


def test_temporal_reference_matches_paper_scaling():
    # Release: zeta / (1 + log(0.2 * ||Pi|| / 1e4 + 1)) == paper: nu = 2e-5 on the raw norm.
    raw_norm = 2500.0
    release = regularization.temporal_reference(raw_norm * 1e-4, 13.0, 0.2)
    paper = 13.0 / (1.0 + np.log(2e-5 * raw_norm + 1.0))
    assert release == pytest.approx(paper)


def test_adaptive_window_replaces_only_the_target_region():
    base = regularization.base_spatial_window((10, 12), (4, 5), 1e5, 1e-3)
    region = regularization.target_region((10, 12), (4, 5))
    assert np.all(base[region] == np.float32(1e-3))
    assert np.sum(base == np.float32(1e-3)) == 20
    variation = np.full((10, 12), np.e - 1.0, dtype=np.float32)
    variation[region[0].start, region[1].start] = np.nan
    window = regularization.adaptive_spatial_window(base, variation, region, 0.2)
    inside = window[region]
    assert inside[0, 0] == np.float32(1e5)  # a non-finite variation never reaches the filter
    np.testing.assert_allclose(inside.ravel()[1:], 0.2, rtol=1e-6)
    outside = window.copy()
    outside[region] = 1e5
    assert np.all(outside == np.float32(1e5))


def test_local_variation_equals_aligning_then_centring_bit_for_bit():
    """The compiled pass (one shift per map, the shifts combined) gives the release's numpy
    align-then-centre Pi exactly, zeros of the previous map (inf, NaN) and float64 maps included."""
    rng = np.random.default_rng(4)
    for shape, dtype in (((50, 50), np.float32), ((37, 44), np.float32), ((38, 41), np.float64)):
        for _ in range(20):
            response, previous = rng.standard_normal((2, *shape)).astype(dtype)
            previous[rng.integers(0, shape[0], 5), rng.integers(0, shape[1], 5)] = 0.0
            response[0, :3] = previous[0, :3] = 0.0  # 0 / 0 wherever the shifts bring them
            shifts = rng.uniform(-25.0, 25.0, 4)
            aligned = np.roll(response, (-math.floor(shifts[0]), -math.floor(shifts[1])), (0, 1))
            before = np.roll(previous, (-math.floor(shifts[2]), -math.floor(shifts[3])), (0, 1))
            with np.errstate(divide="ignore", invalid="ignore"):
                release = np.abs(aligned - before) / np.abs(before)
            release = np.roll(release, (shape[0] // 2, shape[1] // 2), (0, 1))
            got = regularization.local_variation(response, shifts[:2], previous, shifts[2:])
            np.testing.assert_array_equal(got, release.astype(np.float32))


def _full_spectrum_training(x, y, g_prev, window, theta, settings):
    """ADMM of eqs. 8-15 on full complex128 spectra (np.fft.fft2), the h-step taking the real
    part of its inverse: the textbook form the half-spectrum reference stands for."""
    num_cells = window.size
    xf, yf, g_prev_f = np.fft.fft2(x), np.fft.fft2(y), np.fft.fft2(g_prev)
    h_f = l_f = np.zeros_like(xf)
    gamma = settings.gamma_init
    for iteration in range(1, settings.iterations + 1):
        g_f = dcf.g_step(xf, yf, h_f, l_f, g_prev_f, gamma, theta, num_cells)
        if iteration == settings.iterations:
            return g_f
        gain = num_cells / (settings.lambda_spatial * window**2 + gamma * num_cells)
        h_f = np.fft.fft2(gain * np.fft.ifft2(gamma * (g_f + l_f)).real)
        l_f = dcf.multiplier_update(l_f, g_f, h_f, gamma)
        gamma = dcf.next_gamma(gamma, settings)
    return g_f


def test_half_spectrum_training_equals_the_full_complex_one(tmp_path):
    """`dcf.train_filter` on rfft2 half spectra gives the non-negative-frequency half of the
    filter the same ADMM computes on full complex spectra (float32 rounding apart), on the
    feature maps of a real frame; its inverse is a real filter."""
    from autotrack.evaluation.datasets import load_otb_sequence
    from autotrack.io.frames import read_image
    from autotrack.params import TrackerParams
    from autotrack.tracker import features, sampling
    from tests.conftest import REPO

    sequence = load_otb_sequence(REPO / ".." / "shared" / "data" / "sequences" / "OTB" / "Dog1")[0]
    frame = read_image(sequence.frame_paths[0])
    params = TrackerParams()
    grid = (40, 40)
    patch = sampling.search_patch(frame, (130.0, 160.0), (160, 160), (160, 160))
    maps = features.feature_maps(patch, params, None, dcf.cosine_window(grid))
    label = dcf.gaussian_label(grid, 2.0).astype(np.float32)
    g_prev = np.random.default_rng(2).standard_normal(maps.shape).astype(np.float32) * 1e-3
    window = regularization.base_spatial_window(grid, (8, 8), 1e5, 1e-3)
    settings = dcf.admm_settings(params)
    theta = 12.0
    g_half, _ = dcf.train_filter(
        dcf.to_spectrum(maps),
        dcf.to_spectrum(label),
        dcf.to_spectrum(g_prev),
        window,
        theta,
        settings,
    )
    full = _full_spectrum_training(
        maps.astype(np.float64),
        label.astype(np.float64),
        g_prev.astype(np.float64),
        window.astype(np.float64),
        theta,
        settings,
    )
    scale = np.max(np.abs(full))
    assert np.max(np.abs(g_half - full[..., : grid[1] // 2 + 1])) < 1e-4 * scale
    # The full spectrum is Hermitian: its other half is the conjugate mirror of the half.
    spatial = np.fft.ifft2(full)
    assert np.max(np.abs(spatial.imag)) < 1e-10 * np.max(np.abs(spatial.real))
