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

from autotrack.errors import InputError
from autotrack.params import TrackerParams
from autotrack.tracker.colour_terms import COLOUR_TABLE_ROWS, build_lab11_table
from autotrack.tracker.fhog import fhog, fhog_channels

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
    height, width, depth = values.shape
    rows, cols = height // cell, width // cell
    blocks = values[: rows * cell, : cols * cell].astype(np.float32, copy=False)
    sums = blocks.reshape(rows, cell, cols, cell, depth).sum(axis=(1, 3), dtype=np.float32)
    return sums * (np.float32(1.0) / np.float32(cell * cell))


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


def checked_lookup(patch: np.ndarray, table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    rgb, lookup = checked_lookup(patch_rgb_uint8, table)
    index = (rgb[:, :, 0] >> 3) + (rgb[:, :, 1].astype(np.int64) >> 3 << 5)
    index = index + (rgb[:, :, 2].astype(np.int64) >> 3 << 10)
    return cell_average(lookup[index], cell)


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
    """`build_lab11_table()`, read-only, built once per process (~50 ms, on the first
    tracker's first frame); never kept on disk, so no cache file can change a result."""
    table = build_lab11_table()
    table.flags.writeable = False
    return table


def lab11_colour_feature(patch_rgb_uint8: np.ndarray, cell: int) -> np.ndarray:
    """Our default colour feature: cell means of the 'lab11' lookup -> (H//c, W//c, 10)."""
    return colour_table_feature(patch_rgb_uint8, lab11_table(), cell)


# -- the stack ----------------------------------------------------------------------------------


def feature_dim(params: TrackerParams, colour: bool) -> int:
    """Number of channels `extract_features` returns for colour (or grey) patches."""
    channels = GREY_CHANNELS * params.use_grey + FHOG_CHANNELS * params.use_fhog
    if colour and params.colour_feature != "none":
        channels += COLOUR_CHANNELS
    return channels


def feature_patch(patch: np.ndarray, params: TrackerParams, colour_table) -> np.ndarray:
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
) -> np.ndarray:
    """The release's feature stack of one patch, channel-first: float32 (K, H//c, W//c).

    `patch` is uint8 RGB (H x W x 3) or grey (H x W); a grey patch gets no colour channels.
    Order: grey (1), fHOG (31), colour (10), each when enabled in `params`; colour_feature
    'table' uses `colour_table` (a 32768-row table, see `load_colour_table`). Every map is times
    the float32 `window` (H//c, W//c) when one is given.
    """
    array = feature_patch(patch, params, colour_table)
    cell = int(params.cell_size)
    stack = []
    if params.use_grey:
        stack.append(grey_feature(array, cell))
    if params.use_fhog:
        stack.append(fhog(array, cell)[:, :, :FHOG_CHANNELS])
    if array.ndim == 3 and params.colour_feature != "none":
        table = colour_table if params.colour_feature == "table" else lab11_table()
        stack.append(colour_table_feature(array, table, cell))
    maps = np.concatenate(stack, axis=2).transpose(2, 0, 1)
    if window is not None:
        _check_window(window, maps.shape[1:])
        maps = maps * window
    return np.ascontiguousarray(maps, dtype=np.float32)


def _check_window(window: np.ndarray, cells: tuple[int, ...]) -> None:
    if window.shape != cells or window.dtype != np.float32:
        raise InputError(f"the window must be float32 {cells}, got {window.dtype} {window.shape}")


def extract_features(
    patch: np.ndarray, params: TrackerParams, colour_table: np.ndarray | None
) -> np.ndarray:
    """`feature_maps` channel-last: float32 C-contiguous (H//c, W//c, K)."""
    return np.ascontiguousarray(feature_maps(patch, params, colour_table).transpose(1, 2, 0))


def scale_features(patches: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Scale-filter samples: fHOG (cell 4, 31 channels) of each patch, flattened -> (N, D).

    `patches` is (N, h, w) or (N, h, w, 3). Each patch's (h//4, w//4, 31) block is flattened in
    C order (the release uses MATLAB's column-major order; the scale filter only needs one fixed
    order); sample i is times `weights[i]` (the scale window) when weights are given.
    """
    stack = np.asarray(patches)
    if stack.ndim not in (3, 4):
        raise InputError(
            f"scale samples must be N x h x w or N x h x w x 3, got shape {stack.shape}"
        )
    samples = np.stack(
        [fhog(patch, SCALE_FEATURE_CELL)[:, :, :FHOG_CHANNELS].reshape(-1) for patch in stack]
    )
    if weights is not None:
        samples = samples * np.asarray(weights, np.float32)[:, None]
    return samples.astype(np.float32, copy=False)
