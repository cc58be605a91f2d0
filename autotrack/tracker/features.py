"""The tracker's feature stack on a grid of cell x cell pixels: grey, fHOG and a colour feature.

Channel order follows the AutoTrack release: grey (1), fHOG (31), colour (10) for colour
patches; grey and fHOG (32) for grey patches. Everything is float32 of shape
(H // cell, W // cell, K); pixels past the last whole cell are dropped, as the release's
`average_feature_region` and `fhog` do. The tracker's own path, `feature_maps`, writes them
channel-first (K, H // cell, W // cell) and times its cosine window straight into the buffer
its transform reads, each kernel in the pass that computes them.

Colour features:
- 'table': the published Color Names lookup (van de Weijer et al. 2009, normalised 10-D form of
  Danelljan et al. 2014), loaded by the user from a file; it is research data, not ours.
- 'lab11' (default): our own soft assignment of each pixel's CIELAB colour to the 11 English
  basic colour terms, with prototypes from the xkcd colour survey (`colour_terms`),
  projected onto the 10-D subspace orthogonal to the all-ones vector. It is built from colour
  science alone, never from the published table.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
from numba import njit

from autotrack.compile_cache import cached_array
from autotrack.errors import InputError
from autotrack.params import TrackerParams
from autotrack.tracker import colour_terms
from autotrack.tracker.colour_terms import COLOUR_TABLE_ROWS, build_lab11_table
from autotrack.tracker.fhog import fhog_batch, fhog_channels, fhog_weighted_into

GREY_CHANNELS = 1
FHOG_CHANNELS = fhog_channels(9) - 1  # the toolbox's all-zero truncation channel is dropped
COLOUR_CHANNELS = 10
SCALE_FEATURE_CELL = 4
"""The release's scale filter always takes fHOG at cell 4 of its resampled samples."""

RGB2GRAY_WEIGHTS = np.array([0.298936021293775, 0.587043074451121, 0.114020904255103])
"""MATLAB rgb2gray's weights on R, G, B (the luma row of the inverse NTSC YIQ transform)."""

# -- cell averaging and the grey channel ---------------------------------------------------------


def _as_channels(array: np.ndarray) -> np.ndarray:
    array = np.asarray(array)
    if array.ndim == 2:
        return array[:, :, None]
    if array.ndim != 3:
        raise InputError(f"expected an H x W or H x W x K array, got shape {array.shape}")
    return array


def _check_cell(cell_size: int) -> int:
    if int(cell_size) != cell_size or cell_size < 1:
        raise InputError(f"cell size must be a positive integer, got {cell_size}")
    return int(cell_size)


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _cell_means(values, cell, out):
    """Block means of (H, W, K) values into (H//cell, W//cell, K), accumulated in float32."""
    rows, cols, depth = out.shape
    width = cols * cell * depth
    band = np.empty(width, np.float32)
    scale = np.float32(1.0) / np.float32(cell * cell)
    for row in range(rows):
        first = values[row * cell].reshape(-1)[:width]
        for i in range(width):
            band[i] = np.float32(first[i])
        for y in range(row * cell + 1, (row + 1) * cell):
            line = values[y].reshape(-1)[:width]
            for i in range(width):  # whole rows at a time: contiguous, vectorised
                band[i] += np.float32(line[i])
        for col in range(cols):
            for k in range(depth):
                total = np.float32(0.0)
                for dx in range(cell):
                    total += band[(col * cell + dx) * depth + k]
                out[row, col, k] = total * scale


def cell_average(channels: np.ndarray, cell_size: int) -> np.ndarray:
    """Mean over non-overlapping cell x cell blocks from the top-left (average_feature_region).

    H x W or H x W x K of any real dtype in, float32 (H // cell, W // cell, K) out; trailing rows
    and columns that do not fill a whole cell are dropped.
    """
    cell = _check_cell(cell_size)
    values = _as_channels(channels)
    if values.dtype != np.uint8 and values.dtype != np.float32:
        if not np.issubdtype(values.dtype, np.number) or np.iscomplexobj(values):
            raise InputError(f"cell_average needs real numbers, got dtype {values.dtype}")
        values = values.astype(np.float32)
    values = np.ascontiguousarray(values)
    height, width, depth = values.shape
    out = np.empty((height // cell, width // cell, depth), np.float32)
    _cell_means(values, cell, out)
    return out


def is_grey(frame: np.ndarray) -> bool:
    """True for a 2-D (or single-channel) frame, or one whose first two channels are identical.

    Like the release (`all(all(im(:,:,1) == im(:,:,2)))`), only channels 0 and 1 are compared:
    grey images stored as RGB repeat one plane three times, and a single comparison is cheap.
    """
    array = np.asarray(frame)
    if array.ndim == 2 or (array.ndim == 3 and array.shape[2] == 1):
        return True
    if array.ndim != 3 or array.shape[2] < 2:
        raise InputError(f"expected an H x W or H x W x C image, got shape {array.shape}")
    return bool(np.array_equal(array[:, :, 0], array[:, :, 1]))


def grey_feature(patch: np.ndarray, cell_size: int) -> np.ndarray:
    """MATLAB `rgb2gray(single(patch) / 255) - 0.5` averaged over cells -> (H//c, W//c, 1).

    `patch` is RGB (H x W x 3) or single-channel (H x W), 0..255 scale.
    """
    values = _as_channels(patch)
    if values.shape[2] == 3:
        # rgb2gray is linear, so averaging first and weighting after is the same number.
        means = cell_average(values, cell_size)
        grey = means @ (RGB2GRAY_WEIGHTS / 255.0).astype(np.float32)
        return (grey - np.float32(0.5))[:, :, None]
    if values.shape[2] != 1:
        raise InputError(f"grey feature needs 1 or 3 channels, got {values.shape[2]}")
    return cell_average(values, cell_size) / np.float32(255.0) - np.float32(0.5)


# -- colour lookup tables ------------------------------------------------------------------------


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _band_indices(patch, row, cell, index):
    """Table rows R//8 + 32 (G//8) + 1024 (B//8) of the pixels of cell row `row`, (cell, width)."""
    width = index.shape[1]
    for dy in range(cell):
        line = patch[row * cell + dy]
        target = index[dy]
        for x in range(width):
            target[x] = (
                (np.int64(line[x, 0]) >> 3)
                + ((np.int64(line[x, 1]) >> 3) << 5)
                + ((np.int64(line[x, 2]) >> 3) << 10)
            )


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _lookup_cell_average(patch, table, cell, weights, out):
    """Cell means of table[R//8 + 32 (G//8) + 1024 (B//8)] over an RGB uint8 patch, each cell's
    mean times `weights[row, col]` (rounded once after the mean), into `out` of any strides.

    Each cell's sum runs over its pixels row by row, left to right, in float32 from zero; with
    the tables' 10 channels the ten sums stay in registers (no array views, no stores between
    the additions)."""
    rows, cols, depth = out.shape
    index = np.empty((cell, cols * cell), np.int64)
    scale = np.float32(1.0) / np.float32(cell * cell)
    zero = np.float32(0.0)
    for row in range(rows):
        _band_indices(patch, row, cell, index)
        for col in range(cols):
            weight = weights[row, col]
            first = col * cell
            if depth == 10:
                s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = s8 = s9 = zero
                for dy in range(cell):
                    for dx in range(first, first + cell):
                        i = index[dy, dx]
                        s0 += table[i, 0]
                        s1 += table[i, 1]
                        s2 += table[i, 2]
                        s3 += table[i, 3]
                        s4 += table[i, 4]
                        s5 += table[i, 5]
                        s6 += table[i, 6]
                        s7 += table[i, 7]
                        s8 += table[i, 8]
                        s9 += table[i, 9]
                sums = (s0, s1, s2, s3, s4, s5, s6, s7, s8, s9)
                for k in range(10):
                    out[row, col, k] = (sums[k] * scale) * weight
            else:
                for k in range(depth):
                    total = zero
                    for dy in range(cell):
                        for dx in range(first, first + cell):
                            total += table[index[dy, dx], k]
                    out[row, col, k] = (total * scale) * weight


def _as_rgb_uint8(patch: np.ndarray) -> np.ndarray:
    array = np.asarray(patch)
    if array.ndim != 3 or array.shape[2] != 3:
        raise InputError(f"a colour feature needs an H x W x 3 RGB patch, got shape {array.shape}")
    if array.dtype != np.uint8:
        if not np.issubdtype(array.dtype, np.number) or np.iscomplexobj(array):
            raise InputError(f"a colour patch must be real-valued, got dtype {array.dtype}")
        # floor(value / 8) of the release, for values already on the 0..255 scale
        array = np.clip(np.floor(array), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(array)


def _checked_lookup(patch: np.ndarray, table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(RGB uint8 C-contiguous patch, float32 C-contiguous table) for `_lookup_cell_average`."""
    rgb = _as_rgb_uint8(patch)
    lookup = np.asarray(table)
    if lookup.ndim != 2 or lookup.shape[0] != COLOUR_TABLE_ROWS:
        raise InputError(
            f"a colour table must have {COLOUR_TABLE_ROWS} rows (one per RGB bin), got shape {lookup.shape}"
        )
    return rgb, np.ascontiguousarray(lookup, dtype=np.float32)


def colour_table_feature(patch_rgb_uint8: np.ndarray, table: np.ndarray, cell: int) -> np.ndarray:
    """Cell means of a 32768-row colour table indexed by R//8 + 32*(G//8) + 1024*(B//8)."""
    cell = _check_cell(cell)
    rgb, lookup = _checked_lookup(patch_rgb_uint8, table)
    out = np.empty((rgb.shape[0] // cell, rgb.shape[1] // cell, lookup.shape[1]), np.float32)
    _lookup_cell_average(rgb, lookup, cell, np.ones(out.shape[:2], np.float32), out)
    return out


def load_colour_table(path: str | Path) -> np.ndarray:
    """Read a 32768 x 10 Color Names table from `.npy` or `.mat` -> float32, C-contiguous.

    In a `.mat` file the variable `CNnorm` (the release's name) is used when present, otherwise
    the only 32768 x 10 (or 10 x 32768, transposed) numeric array.
    """
    file = Path(path).expanduser()
    if not file.is_file():
        problem = "is not a file" if file.exists() else "does not exist"
        raise InputError(f"colour table {str(file)!r} {problem} (expected a .npy or .mat file)")
    suffix = file.suffix.lower()
    if suffix == ".npy":
        try:
            table = np.load(file, allow_pickle=False)
        except (OSError, ValueError) as error:
            raise InputError(
                f"colour table {str(file)!r} is not a readable .npy file: {error}"
            ) from None
    elif suffix == ".mat":
        table = _table_from_mat(file)
    else:
        raise InputError(
            f"colour table {str(file)!r}: unknown extension {file.suffix!r}; use .npy or .mat"
        )
    table = np.asarray(table)
    if table.shape == (COLOUR_CHANNELS, COLOUR_TABLE_ROWS):
        table = table.T
    if table.shape != (COLOUR_TABLE_ROWS, COLOUR_CHANNELS):
        raise InputError(
            f"colour table {str(file)!r} has shape {table.shape}; expected "
            f"{COLOUR_TABLE_ROWS} x {COLOUR_CHANNELS} (one row per R//8 + 32 G//8 + 1024 B//8 bin)"
        )
    if not np.issubdtype(table.dtype, np.number) or np.iscomplexobj(table):
        raise InputError(f"colour table {str(file)!r} must hold real numbers, got {table.dtype}")
    table = np.ascontiguousarray(table, dtype=np.float32)
    if not np.isfinite(table).all():
        raise InputError(f"colour table {str(file)!r} contains NaN or infinite values")
    return table


def _table_from_mat(file: Path) -> np.ndarray:
    import scipy.io  # only for .mat tables: kept off a tracking process's start-up

    try:
        contents = scipy.io.loadmat(file)
    except (OSError, ValueError, NotImplementedError) as error:
        raise InputError(
            f"colour table {str(file)!r} is not a readable MATLAB file (v7.3/HDF5 files are not "
            f"supported; re-save with save(..., '-v7')): {error}"
        ) from None
    arrays = {
        name: value
        for name, value in contents.items()
        if not name.startswith("__") and isinstance(value, np.ndarray) and value.ndim == 2
        and np.issubdtype(value.dtype, np.number)
    }  # fmt: skip
    if "CNnorm" in arrays:
        return arrays["CNnorm"]
    shaped = [
        value
        for value in arrays.values()
        if value.shape
        in ((COLOUR_TABLE_ROWS, COLOUR_CHANNELS), (COLOUR_CHANNELS, COLOUR_TABLE_ROWS))
    ]
    if len(shaped) == 1:
        return shaped[0]
    found = ", ".join(f"{name} {value.shape}" for name, value in arrays.items()) or "none"
    raise InputError(
        f"colour table {str(file)!r}: expected one {COLOUR_TABLE_ROWS} x {COLOUR_CHANNELS} "
        f"numeric variable (e.g. CNnorm); found {found}"
    )


@lru_cache(maxsize=1)
def lab11_table() -> np.ndarray:
    """`build_lab11_table()`, read-only; kept in the user cache between processes (building it
    takes ~50 ms of a process's start-up, loading it ~1 ms), keyed by `colour_terms`' source and
    numpy's version."""
    key = f"{Path(colour_terms.__file__).read_bytes().hex()} numpy {np.__version__}"
    table = cached_array("lab11", key, build_lab11_table)
    if table.shape != (COLOUR_TABLE_ROWS, COLOUR_CHANNELS) or table.dtype != np.float32:
        table = build_lab11_table()  # a foreign file under our name
    table.flags.writeable = False
    return table


def lab11_colour_feature(patch_rgb_uint8: np.ndarray, cell: int) -> np.ndarray:
    """Our default colour feature: cell means of the 'lab11' lookup -> (H//c, W//c, 10)."""
    return colour_table_feature(patch_rgb_uint8, lab11_table(), cell)


lab11_table()  # loaded (or built) once here, at import, so no tracked frame pays for it


# -- the stack ----------------------------------------------------------------------------------


def feature_dim(params: TrackerParams, colour: bool) -> int:
    """Number of channels `extract_features` returns for colour (or grey) patches."""
    channels = GREY_CHANNELS * params.use_grey + FHOG_CHANNELS * params.use_fhog
    if colour and params.colour_feature != "none":
        channels += COLOUR_CHANNELS
    return channels


def _feature_patch(patch: np.ndarray, params: TrackerParams, colour_table) -> np.ndarray:
    """The patch as H x W (grey) or H x W x 3, checked against the enabled features."""
    array = np.asarray(patch)
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] != 3):
        raise InputError(f"a feature patch must be H x W or H x W x 3, got shape {np.shape(patch)}")
    _check_cell(params.cell_size)
    if array.ndim == 3 and params.colour_feature == "table" and colour_table is None:
        raise InputError(
            "colour_feature='table' needs the Color Names table: load it with load_colour_table"
        )
    if feature_dim(params, array.ndim == 3) == 0:
        raise InputError("no feature enabled: set use_grey, use_fhog or a colour feature")
    return array


def feature_maps(
    patch: np.ndarray,
    params: TrackerParams,
    colour_table: np.ndarray | None,
    window: np.ndarray | None = None,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """The release's feature stack of one patch, channel-first: float32 (K, H//c, W//c).

    `patch` is uint8 RGB (H x W x 3) or grey (H x W); a grey patch gets no colour channels.
    Order: grey (1), fHOG (31), colour (10), each when enabled in `params`; colour_feature
    'table' uses `colour_table` (a 32768-row table, see `load_colour_table`). With a float32
    `window` (H//c, W//c) every map is times the window, taken in the pass that computes it (a
    float32 product rounds once wherever it is taken, so these are exactly the maps times the
    window). Written into `out` (e.g. a transform's input buffer) when given; returned.
    """
    array = _feature_patch(patch, params, colour_table)
    cell = int(params.cell_size)
    shape = (feature_dim(params, array.ndim == 3), array.shape[0] // cell, array.shape[1] // cell)
    if window is None:
        window = np.ones(shape[1:], np.float32)
    if window.shape != shape[1:] or window.dtype != np.float32:
        raise InputError(
            f"the window must be float32 {shape[1:]}, got {window.dtype} {window.shape}"
        )
    if out is None:
        out = np.empty(shape, np.float32)
    elif out.shape != shape or out.dtype != np.float32:
        raise InputError(f"feature maps need a float32 {shape} buffer, got {out.dtype} {out.shape}")
    channel = 0
    if params.use_grey:
        np.multiply(grey_feature(array, cell)[:, :, 0], window, out=out[0])
        channel += GREY_CHANNELS
    if params.use_fhog:
        fhog_weighted_into(array, window, out[channel : channel + FHOG_CHANNELS], cell)
        channel += FHOG_CHANNELS
    if array.ndim == 3 and params.colour_feature != "none":
        table = colour_table if params.colour_feature == "table" else lab11_table()
        rgb, lookup = _checked_lookup(array, table)
        _lookup_cell_average(rgb, lookup, cell, window, out[channel:].transpose(1, 2, 0))
    return out


def extract_features(
    patch: np.ndarray, params: TrackerParams, colour_table: np.ndarray | None
) -> np.ndarray:
    """`feature_maps` channel-last: float32 C-contiguous (H//c, W//c, K)."""
    return np.ascontiguousarray(feature_maps(patch, params, colour_table).transpose(1, 2, 0))


def scale_features(patches: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Scale-filter samples: fHOG (cell 4, 31 channels) of each patch, flattened -> (N, D).

    `patches` is (N, h, w) or (N, h, w, 3). Each patch's (h//4, w//4, 31) block is flattened in
    C order (the release uses MATLAB's column-major order; the scale filter only needs one fixed
    order). With float32 `weights` (N,) sample i is times weights[i] (the scale window), taken in
    the pass that computes it: exactly the unweighted samples times the weights.
    """
    stack = np.asarray(patches)
    if stack.ndim not in (3, 4):
        raise InputError(
            f"scale samples must be N x h x w or N x h x w x 3, got shape {stack.shape}"
        )
    if weights is None:
        weights = np.ones(stack.shape[0], np.float32)
    hog = fhog_batch(stack, SCALE_FEATURE_CELL, sample_weights=weights)
    return hog.reshape(stack.shape[0], -1)
