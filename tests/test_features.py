"""fHOG (Piotr Dollar's toolbox semantics) and the grey / colour feature stack."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import scipy.io

from autotrack.errors import InputError
from autotrack.params import TrackerParams
from autotrack.tracker.backend.fast_fhog import fhog as kernel_fhog
from autotrack.tracker.backend.fast_fhog import fhog_batch
from autotrack.tracker.colour_terms import (
    COLOUR_PROTOTYPES,
    COLOUR_TERMS,
    colour_term_probabilities,
    lab11_projection,
    srgb_to_lab,
)
from autotrack.tracker.features import (
    RGB2GRAY_WEIGHTS,
    cell_average,
    colour_table_feature,
    extract_features,
    feature_dim,
    grey_feature,
    is_grey,
    lab11_colour_feature,
    lab11_table,
    load_colour_table,
    scale_features,
)
from autotrack.tracker.fhog import fhog
from tests.conftest import COLOUR_TABLE, SEQUENCES

PI32 = np.float32(3.14159265)


# -- a slow, literal reference of the toolbox's fhog -------------------------------------------


def toolbox_acos(index: int) -> np.float32:
    """acosTable()[index] of gradientMex.cpp: acos(index / 10000) in float32, padded, clamped."""
    if index < -10000:
        value = PI32
    elif index >= 10000:
        value = np.float32(0.0)
    else:
        value = np.float32(math.acos(np.float32(index) / np.float32(10000)))
    limit = PI32 - np.float32(1e-6)
    if index < 1000 and value > limit:
        value = limit
    return value


def orientation_bin(gx: float, gy: float, n_bins: int) -> int:
    """Hard orientation bin over [0, 2 pi), computed as the toolbox does, in float32."""
    gx, gy = np.float32(gx), np.float32(gy)
    magnitude = np.float32(math.sqrt(gx * gx + gy * gy))
    inverse = (
        np.float32(1e10) if magnitude == 0 else min(np.float32(1) / magnitude, np.float32(1e10))
    )
    cosine = gx * inverse * np.float32(10000)
    if gy < 0:
        cosine = -cosine
    angle = toolbox_acos(int(cosine))
    if gy < 0:
        angle = angle + PI32
    per_radian = np.float32(n_bins) / (np.float32(2) * PI32)
    index = int(angle * per_radian + np.float32(0.5))
    return 0 if index >= n_bins else index


def reference_fhog(image: np.ndarray, cell: int = 4, n_orients: int = 9, clip: float = 0.2):
    """fhog from the written rules, with plain loops (needs at least 2 x 2 cells)."""
    img = np.asarray(image, dtype=np.float64)
    if img.ndim == 2:
        img = img[:, :, None]
    hb, wb = img.shape[0] // cell, img.shape[1] // cell
    n_bins = 2 * n_orients
    gx = np.empty_like(img)
    gy = np.empty_like(img)
    gx[:, 1:-1] = (img[:, 2:] - img[:, :-2]) / 2
    gx[:, 0] = img[:, 1] - img[:, 0]
    gx[:, -1] = img[:, -1] - img[:, -2]
    gy[1:-1] = (img[2:] - img[:-2]) / 2
    gy[0] = img[1] - img[0]
    gy[-1] = img[-1] - img[-2]
    strongest = np.argmax(gx**2 + gy**2, axis=2)  # first channel among equal maxima
    sensitive = np.zeros((hb, wb, n_bins))
    for y in range(hb * cell):
        for x in range(wb * cell):
            c = strongest[y, x]
            o = orientation_bin(gx[y, x, c], gy[y, x, c], n_bins)
            m = math.hypot(gx[y, x, c], gy[y, x, c]) / cell**2
            yb, xb = (y + 0.5) / cell - 0.5, (x + 0.5) / cell - 0.5
            y0, x0 = math.floor(yb), math.floor(xb)
            for cy, wy in ((y0, 1 - (yb - y0)), (y0 + 1, yb - y0)):
                for cx, wx in ((x0, 1 - (xb - x0)), (x0 + 1, xb - x0)):
                    if 0 <= cy < hb and 0 <= cx < wb:
                        sensitive[cy, cx, o] += wy * wx * m
    gain = np.ones((hb, wb))
    for border in (np.s_[0, :], np.s_[-1, :], np.s_[:, 0], np.s_[:, -1]):
        gain[border] *= 8 / 7
    sensitive *= gain[:, :, None]
    insensitive = sensitive[:, :, :n_orients] + sensitive[:, :, n_orients:]
    energy = (insensitive**2).sum(axis=2)
    norm = np.zeros((hb + 1, wb + 1))
    for i in range(hb - 1):
        for j in range(wb - 1):
            norm[i + 1, j + 1] = 1 / math.sqrt(
                energy[i : i + 2, j : j + 2].sum() + 1e-4 / 4 / cell**4
            )
    norm = norm[np.clip(np.arange(hb + 1), 1, hb - 1)][:, np.clip(np.arange(wb + 1), 1, wb - 1)]
    out = np.zeros((hb, wb, 3 * n_orients + 5))
    for i in range(hb):
        for j in range(wb):
            blocks = [norm[i + 1 - b % 2, j + 1 - b // 2] for b in range(4)]
            for o in range(n_bins):
                clipped = [min(sensitive[i, j, o] * n, clip) for n in blocks]
                out[i, j, o] = 0.5 * sum(clipped)
                for b in range(4):
                    out[i, j, 3 * n_orients + b] += 0.2357 * clipped[b]
            for o in range(n_orients):
                out[i, j, n_bins + o] = 0.5 * sum(
                    min(insensitive[i, j, o] * n, clip) for n in blocks
                )
    return out


# -- fhog -------------------------------------------------------------------------------------


@pytest.mark.parametrize("channels", [None, 2, 3, 4])  # grey, RGB and the general choice
def test_fhog_matches_the_written_reference_on_random_images(channels):
    rng = np.random.default_rng(7 if channels else 11)
    for _ in range(3):
        shape = (12, 16) if channels is None else (12, 16, channels)
        image = rng.integers(0, 256, shape).astype(np.uint8)
        np.testing.assert_allclose(fhog(image), reference_fhog(image), atol=1e-5, rtol=0)


def test_fhog_matches_the_reference_when_size_is_not_a_multiple_of_the_cell():
    image = np.random.default_rng(3).integers(0, 256, (14, 19, 3)).astype(np.uint8)
    result = fhog(image)
    assert result.shape == (3, 4, 32)
    np.testing.assert_allclose(result, reference_fhog(image), atol=1e-5, rtol=0)


# The toolbox's own output for GOLDEN_IMAGE: gradientMex.cpp (v3.30) compiled with g++ -msse2
# and run through fhog.m's two calls. Sums over the 3 x 4 cells per channel. Our port differs
# only by the SSE rcp/rsqrt approximations the C code uses (about 3e-5 per entry here).
GOLDEN_IMAGE = np.array(
    [
        [168, 206, 224, 213, 176, 129, 90, 76, 89, 120, 151, 164, 150, 113, 68, 36],
        [185, 218, 226, 204, 161, 117, 88, 86, 109, 142, 167, 168, 142, 98, 55, 30],
        [198, 225, 223, 193, 150, 113, 97, 109, 139, 171, 187, 175, 138, 90, 50, 35],
        [196, 215, 205, 173, 135, 111, 112, 137, 174, 204, 210, 187, 143, 95, 62, 57],
        [175, 184, 166, 133, 104, 96, 115, 154, 197, 224, 224, 195, 151, 110, 90, 97],
        [150, 142, 113, 78, 56, 61, 93, 141, 186, 209, 203, 174, 137, 112, 111, 135],
        [162, 134, 90, 49, 29, 38, 73, 117, 151, 161, 145, 112, 83, 73, 91, 132],
        [208, 171, 123, 84, 69, 82, 113, 145, 159, 146, 110, 67, 35, 30, 55, 98],
        [193, 161, 126, 107, 115, 145, 185, 214, 218, 193, 148, 102, 73, 71, 94, 128],
        [116, 78, 49, 44, 68, 113, 160, 192, 196, 173, 139, 111, 105, 125, 164, 203],
        [147, 98, 65, 59, 79, 114, 143, 151, 133, 95, 56, 33, 39, 72, 119, 161],
        [139, 109, 100, 118, 156, 198, 224, 222, 192, 147, 105, 84, 91, 119, 151, 170],
    ],
    dtype=np.uint8,
)
GOLDEN_GREY_CHANNEL_SUMS = [
    1.285821, 1.216751, 1.175517, 2.51145, 1.18054, 0.857879, 0.907432, 0.795401, 1.924937,
    1.833244, 1.925745, 1.28874, 2.952484, 0.691341, 0.511002, 0.545813, 0.492531, 1.364069,
    3.01021, 2.737994, 2.329154, 4.262956, 1.87188, 1.368882, 1.377882, 1.287932, 3.201414,
    2.737032, 2.83228, 2.685423, 2.804637, 0.0,
]  # fmt: skip
GOLDEN_COLOUR_CHANNEL_SUMS = [
    1.798155, 1.26853, 1.644603, 2.573503, 0.805457, 0.236856, 0.619524, 0.299626, 1.083768,
    1.825834, 2.153562, 1.241654, 3.140406, 0.375624, 0.148615, 0.130866, 0.285738, 1.090405,
    3.410111, 2.918789, 2.83947, 4.001324, 1.181081, 0.385471, 0.75039, 0.585364, 2.174172,
    2.448107, 2.472438, 2.416246, 2.431902, 0.0,
]  # fmt: skip


def golden_colour_image() -> np.ndarray:
    columns = np.arange(16, dtype=np.uint8)[None, :] * np.uint8(7)
    grey = GOLDEN_IMAGE
    blue = (np.uint8(255) - grey) // np.uint8(2) + columns  # uint8 arithmetic, as generated
    return np.stack([grey, np.roll(grey, 3, axis=1), blue], axis=-1)


def test_fhog_agrees_with_the_compiled_toolbox_output():
    grey_sums = fhog(GOLDEN_IMAGE).sum(axis=(0, 1))
    colour_sums = fhog(golden_colour_image()).sum(axis=(0, 1))
    np.testing.assert_allclose(grey_sums, GOLDEN_GREY_CHANNEL_SUMS, atol=3e-4, rtol=0)
    np.testing.assert_allclose(colour_sums, GOLDEN_COLOUR_CHANNEL_SUMS, atol=3e-4, rtol=0)


def test_fhog_shape_dtype_and_value_ranges():
    image = np.random.default_rng(0).integers(0, 256, (43, 61, 3)).astype(np.uint8)
    result = fhog(image)
    assert result.shape == (10, 15, 32)
    assert result.dtype == np.float32
    assert (result >= 0).all()
    assert result[:, :, :27].max() <= 0.4 + 1e-6  # 4 blocks * 0.5 * clip
    assert result[:, :, 27:31].max() <= 0.2357 * 18 * 0.2 + 1e-6
    assert result[:, :, 27:31].max() > 0
    assert not result[:, :, 31].any()


def test_constant_image_has_all_zero_features():
    result = fhog(np.full((24, 20, 3), 117, dtype=np.uint8))
    assert np.isfinite(result).all()
    assert not result.any()


def ramp_features(image: np.ndarray) -> dict[int, float]:
    """Non-zero channels of the (identical) cells of a ramp image."""
    result = fhog(image.astype(np.float32))
    assert np.allclose(result, result[0, 0])
    return {int(c): float(result[0, 0, c]) for c in np.flatnonzero(result[0, 0])}


TEXTURE = 0.2357 * 0.2  # one clipped bin in each of the 4 blocks


@pytest.mark.parametrize(
    ("ramp", "sensitive_bin"),
    [
        ("right", 0),  # gradient along +x: angle 0
        ("down", 5),  # +y (rows grow downwards): float32(pi/2) * 18/(2 pi) + 0.5 == 5.0 exactly
        ("left", 9),  # angle pi - 1e-6 (the table's clamp): 9.4999 + 0.5 -> bin 9
        ("up", 14),  # 3 pi / 2 -> 13.5 + 0.5 -> 14
        ("diagonal", 2),  # pi / 4 -> 2.25 + 0.5 -> 2
    ],
)
def test_ramp_images_land_in_the_hand_computed_bin(ramp, sensitive_bin):
    y, x = np.mgrid[0:8, 0:8]
    image = {"right": 10 * x, "down": 10 * y, "left": 70 - 10 * x, "up": 70 - 10 * y}.get(
        ramp, 10 * (x + y)
    )
    # Every cell of the 2 x 2 grid gets magnitude/16 x (3.5 x 3.5 pixel weights) x (8/7)^2 =
    # the gradient magnitude itself; the block normaliser 1/(2 |g|) then gives 0.5, clipped to 0.2.
    expected = {
        sensitive_bin: 0.4,
        18 + sensitive_bin % 9: 0.4,
        27: TEXTURE,
        28: TEXTURE,
        29: TEXTURE,
        30: TEXTURE,
    }
    features = ramp_features(image)
    assert features.keys() == expected.keys()
    for channel, value in expected.items():
        assert features[channel] == pytest.approx(value, abs=1e-6)


def test_fhog_batch_equals_fhog_one_by_one():
    patches = np.random.default_rng(5).integers(0, 256, (6, 32, 16, 3)).astype(np.uint8)
    batch = fhog_batch(patches)
    assert batch.shape == (6, 8, 4, 32)
    for patch, features in zip(patches, batch, strict=True):
        np.testing.assert_array_equal(features, kernel_fhog(patch))


@pytest.mark.parametrize(
    "shape",
    [(33, 22, 22, 3), (5, 27, 18, 3), (4, 4, 26, 3), (7, 22, 22), (3, 21, 13, 2), (2, 9, 3, 3)],
)
def test_fhog_batch_side_by_side_equals_each_image_alone(shape):
    """The batch takes its images' histograms side by side in one long row: every image's own
    borders (one-sided gradients, edge cells), its unused last columns and its weight stay
    its own, bit for bit, in colour, grey and other channel counts, and for widths that leave
    columns over or no whole cell at all."""
    rng = np.random.default_rng(sum(shape))
    smooth = cv2.GaussianBlur(rng.integers(0, 256, (64, 64, 3), dtype=np.uint8), (0, 0), 2)
    count, height, width = shape[:3]
    patches = np.stack(
        [
            cv2.resize(smooth[i : i + 20 + 2 * i, i : i + 25 + i], (width, height))
            for i in range(count)
        ]
    )
    channels = shape[3] if len(shape) == 4 else 1
    patches = np.ascontiguousarray(patches[..., :channels]).reshape(shape)
    weights = rng.uniform(0.5, 1.5, count).astype(np.float32)
    batch = fhog_batch(patches, sample_weights=weights)
    for patch, weight, features in zip(patches, weights, batch, strict=True):
        np.testing.assert_array_equal(features, kernel_fhog(patch)[..., :-1] * weight)


def test_fhog_accepts_any_real_dtype():
    image = np.random.default_rng(9).integers(0, 256, (16, 20)).astype(np.uint8)
    reference = fhog(image)
    np.testing.assert_array_equal(fhog(image.astype(np.float64)), reference)
    np.testing.assert_array_equal(fhog(image.astype(np.int32)), reference)
    np.testing.assert_array_equal(fhog(image[:, :, None]), reference)


def test_fhog_rejects_bad_input():
    with pytest.raises(InputError, match="at least 2 x 2"):
        fhog(np.zeros((1, 8)))
    with pytest.raises(InputError, match="H x W"):
        fhog(np.zeros((2, 8, 8, 3)))
    with pytest.raises(InputError, match="cell_size"):
        fhog(np.zeros((8, 8)), cell_size=0)
    with pytest.raises(InputError, match="N x H x W"):
        fhog_batch(np.zeros((8, 8)))


# -- cell averaging, grey -----------------------------------------------------------------------


def test_cell_average_of_a_hand_computed_case():
    y, x = np.mgrid[0:5, 0:9]
    values = 10 * y + x  # the last row and column do not fill a 2 x 2 cell
    result = cell_average(values, 2)
    assert result.shape == (2, 4, 1)
    assert result.dtype == np.float32
    i, j = np.mgrid[0:2, 0:4]
    np.testing.assert_allclose(result[:, :, 0], 20 * i + 2 * j + 5.5)


def test_cell_average_per_channel():
    values = np.random.default_rng(1).random((9, 13, 4)).astype(np.float32)
    expected = values[:8, :12].reshape(2, 4, 3, 4, 4).mean(axis=(1, 3))
    np.testing.assert_allclose(cell_average(values, 4), expected, rtol=1e-6)


def test_is_grey_compares_the_first_two_channels():
    rng = np.random.default_rng(2)
    plane = rng.integers(0, 256, (6, 7)).astype(np.uint8)
    assert is_grey(plane)
    assert is_grey(np.stack([plane] * 3, axis=-1))
    coloured = np.stack([plane, plane + 1, plane], axis=-1)
    assert not is_grey(coloured)
    # Only channels 0 and 1 are compared, as in the release.
    assert is_grey(np.stack([plane, plane, plane // 2], axis=-1))


def test_grey_feature_is_matlab_rgb2gray_minus_half():
    rng = np.random.default_rng(4)
    patch = rng.integers(0, 256, (16, 12, 3)).astype(np.uint8)
    result = grey_feature(patch, 4)
    grey = patch.astype(np.float64) @ RGB2GRAY_WEIGHTS / 255 - 0.5
    expected = grey.reshape(4, 4, 3, 4).mean(axis=(1, 3))[:, :, None]
    assert result.shape == (4, 3, 1)
    np.testing.assert_allclose(result, expected, atol=1e-6)
    assert grey_feature(np.full((4, 4, 3), 255, np.uint8), 4)[0, 0, 0] == pytest.approx(0.5)
    assert grey_feature(np.zeros((4, 4, 3), np.uint8), 4)[0, 0, 0] == pytest.approx(-0.5)
    single = grey_feature(patch[:, :, 1], 4)
    np.testing.assert_allclose(single, cell_average(patch[:, :, 1], 4) / 255 - 0.5, atol=1e-6)


# -- colour tables ------------------------------------------------------------------------------


def table_index(rgb: np.ndarray) -> np.ndarray:
    rgb = rgb.astype(np.int64)
    return rgb[..., 0] // 8 + 32 * (rgb[..., 1] // 8) + 1024 * (rgb[..., 2] // 8)


def test_colour_table_feature_is_the_cell_mean_of_the_lookup():
    rng = np.random.default_rng(6)
    table = rng.normal(size=(32768, 10)).astype(np.float32)
    patch = rng.integers(0, 256, (13, 10, 3)).astype(np.uint8)
    result = colour_table_feature(patch, table, 4)
    expected = table[table_index(patch[:12, :8])].reshape(3, 4, 2, 4, 10).mean(axis=(1, 3))
    assert result.shape == (3, 2, 10)
    np.testing.assert_allclose(result, expected, atol=1e-5)


@pytest.fixture(scope="module")
def published_table() -> np.ndarray:
    if not COLOUR_TABLE.is_file():
        pytest.skip(f"published Color Names table not found at {COLOUR_TABLE}")
    return load_colour_table(COLOUR_TABLE)


def test_published_table_loads_and_a_uniform_patch_returns_its_row(published_table):
    assert published_table.shape == (32768, 10)
    assert published_table.dtype == np.float32
    colour = np.array([200, 40, 90], dtype=np.uint8)
    patch = np.broadcast_to(colour, (8, 12, 3)).copy()
    result = colour_table_feature(patch, published_table, 4)
    row = published_table[table_index(colour)]
    np.testing.assert_allclose(result, np.broadcast_to(row, (2, 3, 10)), atol=1e-6)


def test_table_feature_rows_sum_like_the_table_rows(published_table):
    patch = np.random.default_rng(8).integers(0, 256, (8, 8, 3)).astype(np.uint8)
    sums = colour_table_feature(patch, published_table, 4).sum(axis=2)
    row_sums = published_table.sum(axis=1)[table_index(patch)]
    np.testing.assert_allclose(sums, row_sums.reshape(2, 4, 2, 4).mean(axis=(1, 3)), atol=1e-5)


def test_load_colour_table_from_npy_and_mat(tmp_path):
    table = np.random.default_rng(10).random((32768, 10))
    np.save(tmp_path / "cn.npy", table)
    np.testing.assert_allclose(load_colour_table(tmp_path / "cn.npy"), table, rtol=1e-6)
    scipy.io.savemat(tmp_path / "named.mat", {"CNnorm": table, "other": np.ones((3, 3))})
    np.testing.assert_allclose(load_colour_table(tmp_path / "named.mat"), table, rtol=1e-6)
    scipy.io.savemat(tmp_path / "transposed.mat", {"w2c": table.T})
    np.testing.assert_allclose(load_colour_table(tmp_path / "transposed.mat"), table, rtol=1e-6)


def test_load_colour_table_errors_are_actionable(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_colour_table(tmp_path / "missing.npy")
    (tmp_path / "table.txt").write_text("1 2 3")
    with pytest.raises(InputError, match="unknown extension"):
        load_colour_table(tmp_path / "table.txt")
    np.save(tmp_path / "small.npy", np.zeros((100, 10)))
    with pytest.raises(InputError, match="32768 x 10"):
        load_colour_table(tmp_path / "small.npy")
    scipy.io.savemat(tmp_path / "none.mat", {"a": np.zeros((5, 5))})
    with pytest.raises(InputError, match="CNnorm"):
        load_colour_table(tmp_path / "none.mat")
    broken = np.zeros((32768, 10))
    broken[3, 4] = np.nan
    np.save(tmp_path / "nan.npy", broken)
    with pytest.raises(InputError, match="NaN"):
        load_colour_table(tmp_path / "nan.npy")
    (tmp_path / "corrupt.npy").write_bytes(b"not a numpy file")
    with pytest.raises(InputError, match="not a readable"):
        load_colour_table(tmp_path / "corrupt.npy")


# -- lab11: our own colour feature ---------------------------------------------------------------


def test_srgb_to_lab_reference_values():
    np.testing.assert_allclose(srgb_to_lab([255, 255, 255]), [100, 0, 0], atol=0.01)
    np.testing.assert_allclose(srgb_to_lab([0, 0, 0]), [0, 0, 0], atol=1e-9)
    np.testing.assert_allclose(srgb_to_lab([255, 0, 0]), [53.24, 80.09, 67.20], atol=0.05)
    np.testing.assert_allclose(srgb_to_lab([0, 0, 255]), [32.30, 79.19, -107.86], atol=0.05)


def test_lab11_prototypes_are_the_xkcd_survey_colours():
    xkcd = pytest.importorskip("matplotlib.colors").XKCD_COLORS
    for term, prototypes in COLOUR_PROTOTYPES.items():
        names = [term] if term in ("black", "white") else [term, f"light {term}", f"dark {term}"]
        assert [xkcd[f"xkcd:{name}"].lstrip("#") for name in names] == list(prototypes)


@pytest.mark.parametrize(
    ("rgb", "term"),
    [
        ((255, 0, 0), "red"),
        ((0, 255, 0), "green"),
        ((0, 0, 255), "blue"),
        ((255, 255, 0), "yellow"),
        ((255, 255, 255), "white"),
        ((0, 0, 0), "black"),
        ((128, 128, 128), "grey"),
        ((255, 128, 0), "orange"),
        ((255, 170, 200), "pink"),
        ((128, 0, 128), "purple"),
        ((120, 70, 30), "brown"),
        ((128, 0, 0), "red"),  # maroon: dark red, not brown
        ((0, 0, 128), "blue"),  # navy: CIELAB alone would call it purple
    ],
)
def test_lab11_assigns_most_weight_to_the_named_term(rgb, term):
    probabilities = colour_term_probabilities(np.array(rgb))
    assert probabilities.sum() == pytest.approx(1.0)
    assert COLOUR_TERMS[int(np.argmax(probabilities))] == term
    assert probabilities.max() > 0.5


def test_lab11_projection_loses_nothing():
    projection = lab11_projection()
    np.testing.assert_allclose(projection @ projection.T, np.eye(10), atol=1e-12)
    np.testing.assert_allclose(projection @ np.ones(11), 0, atol=1e-12)
    probabilities = colour_term_probabilities(np.array([[30, 160, 70], [250, 240, 230]]))
    recovered = (probabilities @ projection.T) @ projection + 1 / 11
    np.testing.assert_allclose(recovered, probabilities, atol=1e-12)


def test_lab11_table_and_feature():
    table = lab11_table()
    assert table.shape == (32768, 10)
    assert table.dtype == np.float32
    assert not table.flags.writeable
    assert lab11_table() is table  # built once
    colour = np.array([60, 130, 210], dtype=np.uint8)
    bin_centre = (colour // 8) * 8 + 3.5
    expected = colour_term_probabilities(bin_centre) @ lab11_projection().T
    np.testing.assert_allclose(table[table_index(colour)], expected, atol=1e-6)
    patch = np.broadcast_to(colour, (8, 8, 3)).copy()
    result = lab11_colour_feature(patch, 4)
    np.testing.assert_allclose(result, np.broadcast_to(expected, (2, 2, 10)), atol=1e-6)


# -- the stack --------------------------------------------------------------------------------


def test_extract_features_channel_order_for_colour_patches():
    rng = np.random.default_rng(12)
    patch = rng.integers(0, 256, (40, 36, 3)).astype(np.uint8)
    params = TrackerParams()
    result = extract_features(patch, params, None)
    assert result.shape == (10, 9, 42) == (10, 9, feature_dim(params, colour=True))
    assert result.dtype == np.float32
    assert result.flags.c_contiguous
    np.testing.assert_array_equal(result[:, :, :1], grey_feature(patch, 4))
    np.testing.assert_array_equal(result[:, :, 1:32], fhog(patch)[:, :, :31])
    np.testing.assert_array_equal(result[:, :, 32:], lab11_colour_feature(patch, 4))
    assert result[:, :, 0].min() >= -0.5 and result[:, :, 0].max() <= 0.5


def test_extract_features_grey_patch_has_no_colour_channels():
    patch = np.random.default_rng(13).integers(0, 256, (40, 36)).astype(np.uint8)
    params = TrackerParams()
    result = extract_features(patch, params, None)
    assert result.shape == (10, 9, 32) == (10, 9, feature_dim(params, colour=False))
    np.testing.assert_array_equal(result[:, :, 1:], fhog(patch)[:, :, :31])


def test_extract_features_honours_the_parameters():
    rng = np.random.default_rng(14)
    patch = rng.integers(0, 256, (24, 24, 3)).astype(np.uint8)
    table = rng.normal(size=(32768, 10)).astype(np.float32)
    with_table = dataclasses.replace(TrackerParams(), colour_feature="table")
    result = extract_features(patch, with_table, table)
    np.testing.assert_array_equal(result[:, :, 32:], colour_table_feature(patch, table, 4))
    with pytest.raises(InputError, match="load_colour_table"):
        extract_features(patch, with_table, None)
    no_colour = dataclasses.replace(TrackerParams(), colour_feature="none")
    assert extract_features(patch, no_colour, None).shape == (6, 6, 32)
    hog_only = dataclasses.replace(no_colour, use_grey=False)
    np.testing.assert_array_equal(extract_features(patch, hog_only, None), fhog(patch)[:, :, :31])
    grey_only = dataclasses.replace(no_colour, use_fhog=False)
    assert feature_dim(grey_only, colour=True) == 1
    with pytest.raises(InputError, match="enable at least one feature"):
        dataclasses.replace(grey_only, use_grey=False)
    with pytest.raises(InputError, match="H x W x 3"):
        extract_features(np.zeros((8, 8, 4), np.uint8), TrackerParams(), None)


def test_scale_features_flatten_each_patch_in_c_order():
    patches = np.random.default_rng(15).integers(0, 256, (5, 32, 16, 3)).astype(np.uint8)
    result = scale_features(patches)
    assert result.shape == (5, 8 * 4 * 31)
    assert result.dtype == np.float32
    for patch, row in zip(patches, result, strict=True):
        np.testing.assert_array_equal(row, fhog(patch)[:, :, :31].reshape(-1))


# -- real frames ------------------------------------------------------------------------------


def read_rgb(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert image is not None, path
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def first_frame(sequence: str) -> Path:
    frames = sorted((SEQUENCES / sequence / "img").glob("*.jpg"))
    if not frames:
        pytest.skip(f"sequence {sequence} not found under {SEQUENCES}")
    return frames[0]


def test_features_of_a_real_colour_frame():
    frame = read_rgb(first_frame("UAV123_10fps/boat5"))
    assert not is_grey(frame)
    patch = np.ascontiguousarray(frame[300:500, 500:700])
    result = extract_features(patch, TrackerParams(), None)
    assert result.shape == (50, 50, 42)
    assert np.isfinite(result).all()
    assert result[:, :, 1:28].max() <= 0.4 + 1e-6
    assert result[:, :, 1:32].min() >= 0
    # Real texture: most cells carry gradient energy, and several colour terms appear.
    assert (result[:, :, 28:32].sum(axis=2) > 0).mean() > 0.9
    assert result[:, :, 32:].std(axis=(0, 1)).max() > 0.01


def test_features_of_a_real_grey_frame():
    frame = read_rgb(first_frame("OTB/Dog1"))
    assert frame.ndim == 2 and is_grey(frame)
    result = extract_features(np.ascontiguousarray(frame[40:200, 60:260]), TrackerParams(), None)
    assert result.shape == (40, 50, 32)
    assert np.isfinite(result).all()
