"""OpenCV's INTER_AREA shrink, bit for bit, fused with the border-replicating crop.

The release samples its search patch and its 33 scale samples with mexResize 'auto' (OpenCV
INTER_AREA when shrinking). Calling `cv2.resize` once per sample costs a crop (a copy with
`copyMakeBorder` near the border), a Python round trip and OpenCV's generic area loop, which
keeps its per-tap sums in memory; on large targets those 34 calls were a third of a frame.

This module computes the same uint8 samples in one compiled call per frame: the crop is folded
into clamped row/column index maps (pixels outside the image are the border ones, as in
`sampling.crop_replicate`), and the area weights and the float32 accumulation follow OpenCV's
`computeResizeAreaTab` and `ResizeArea_Invoker` operation for operation (the same taps in the
same order, float32 products and sums, rounding half to even), so every sample equals
`cv2.resize(crop, size, interpolation=cv2.INTER_AREA)` exactly. Cases OpenCV handles with
another algorithm -- an integer ratio on both axes (its `resizeAreaFast` path), or enlarging
along either axis -- are reported by `area_path_is_generic` and left to `cv2.resize`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numba import njit

_DBL_EPSILON = np.finfo(np.float64).eps


def _opencv_round(value: float) -> int:
    """cvRound / saturate_cast<int> of a double: nearest, halves to even."""
    return int(round(value))


def area_path_is_generic(src_hw: tuple[int, int], dst_hw: tuple[int, int]) -> bool:
    """True when cv2.resize(INTER_AREA) takes its generic table path for these sizes.

    That is: shrinking (or keeping) both axes, not the same size, and not an integer ratio on
    both axes (OpenCV's `is_area_fast`, which averages with integer sums instead).
    """
    src_h, src_w = int(src_hw[0]), int(src_hw[1])
    dst_h, dst_w = int(dst_hw[0]), int(dst_hw[1])
    if (src_h, src_w) == (dst_h, dst_w):
        return False
    scale_x = 1.0 / (dst_w / src_w)  # as cv::resize computes it: 1. / inv_scale_x
    scale_y = 1.0 / (dst_h / src_h)
    if scale_x < 1.0 or scale_y < 1.0:
        return False
    fast = (
        abs(scale_x - _opencv_round(scale_x)) < _DBL_EPSILON
        and abs(scale_y - _opencv_round(scale_y)) < _DBL_EPSILON
    )
    return not fast


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _generic_paths(sizes, dst_h, dst_w):
    """`area_path_is_generic` of each (rows, cols) row of `sizes`, in the same float64 steps."""
    generic = np.empty(sizes.shape[0], np.bool_)
    for i in range(sizes.shape[0]):
        src_h, src_w = sizes[i, 0], sizes[i, 1]
        scale_x = 1.0 / (dst_w / src_w)
        scale_y = 1.0 / (dst_h / src_h)
        same = src_h == dst_h and src_w == dst_w
        fast = abs(scale_x - np.rint(scale_x)) < _DBL_EPSILON and (
            abs(scale_y - np.rint(scale_y)) < _DBL_EPSILON
        )  # a fractional part of exactly 0.5 is never fast: the rounding of halves is moot
        generic[i] = scale_x >= 1.0 and scale_y >= 1.0 and not same and not fast
    return generic


def area_paths_are_generic(sizes_hw: np.ndarray, dst_hw: tuple[int, int]) -> np.ndarray:
    """`area_path_is_generic` for each row of an (N, 2) array of source sizes, in one call."""
    sizes = np.ascontiguousarray(sizes_hw, dtype=np.int64).reshape(-1, 2)
    return _generic_paths(sizes, int(dst_hw[0]), int(dst_hw[1]))


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _area_taps(src_size, dst_size, first, weights, offsets):
    """computeResizeAreaTab for one axis: source index and float32 weight of every tap.

    Taps of destination index d are first[offsets[d]:offsets[d + 1]] (consecutive source
    indices, in OpenCV's order) with the matching weights. Returns the tap count.
    """
    inv_scale = dst_size / src_size
    scale = 1.0 / inv_scale
    k = 0
    for dx in range(dst_size):
        offsets[dx] = k
        fsx1 = dx * scale
        fsx2 = fsx1 + scale
        cell_width = min(scale, src_size - fsx1)
        sx1 = math.ceil(fsx1)
        sx2 = math.floor(fsx2)
        sx2 = min(sx2, src_size - 1)
        sx1 = min(sx1, sx2)
        if sx1 - fsx1 > 1e-3:
            first[k] = sx1 - 1
            weights[k] = np.float32((sx1 - fsx1) / cell_width)
            k += 1
        for sx in range(sx1, sx2):
            first[k] = sx
            weights[k] = np.float32(1.0 / cell_width)
            k += 1
        if fsx2 - sx2 > 1e-3:
            first[k] = sx2
            weights[k] = np.float32(min(min(fsx2 - sx2, 1.0), cell_width) / cell_width)
            k += 1
    offsets[dst_size] = k
    return k


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _transposed_region(image, top, left, rows, cols):
    """float32 (C, cols, rows) copy of a region, rows clamped into the image (replicated border).

    Transposed so that the horizontal pass below runs over contiguous rows: every output
    element's float32 operations stay in OpenCV's order, and the compiler vectorises across rows.
    """
    height, width, channels = image.shape
    region = np.empty((channels, cols, rows), np.float32)
    column_index = np.empty(cols, np.uint64)  # unsigned: no negative-index test when indexing
    for q in range(cols):
        column_index[q] = min(max(left + q, 0), width - 1)
    row_index = np.empty(rows, np.uint64)
    for r in range(rows):
        row_index[r] = min(max(top + r, 0), height - 1)
    block = 16  # rows per pass: reads stay in a few cache lines, writes are contiguous runs
    for r0 in range(0, rows, block):
        r1 = min(r0 + block, rows)
        for q in range(cols):
            x = column_index[q]
            for c in range(channels):
                target = region[c, q]
                for r in range(r0, r1):
                    target[r] = np.float32(image[row_index[r], x, c])
    return region


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _vertical_pass(horizontal, y_src, y_weight, y_offsets, out, total):
    """ResizeArea_Invoker's vertical pass: out[dy] = saturate_cast<uchar> (half to even) of the
    sum over y taps of beta * horizontal[y] (rows of dst_w * channels interleaved sums), the
    taps in OpenCV's order, vectorised along the row; `total` holds one row."""
    row_width = out.shape[1] * out.shape[2]
    rows_out = out.reshape(out.shape[0], row_width)
    for dy in range(out.shape[0]):
        first = y_offsets[dy]
        source = horizontal[y_src[first]]
        beta = y_weight[first]
        for i in range(row_width):
            total[i] = beta * source[i]
        for j in range(first + 1, y_offsets[dy + 1]):
            source = horizontal[y_src[j]]
            beta = y_weight[j]
            for i in range(row_width):
                total[i] = total[i] + beta * source[i]
        row = rows_out[dy]
        for i in range(row_width):
            value = np.rint(total[i])
            row[i] = np.uint8(min(max(value, np.float32(0.0)), np.float32(255.0)))


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _region_buffers(channels, max_h, max_w, dst_h, dst_w):
    """Scratch arrays of `_area_from_region` for crops up to max_h x max_w: allocated once for
    all the crops of a call (x taps, y taps, a column's sums, the row-major sums with channels
    interleaved, an output row)."""
    return (
        np.empty(2 * max_w + 2, np.int64),
        np.empty(2 * max_w + 2, np.float32),
        np.empty(dst_w + 1, np.int64),
        np.empty(2 * max_h + 2, np.int64),
        np.empty(2 * max_h + 2, np.float32),
        np.empty(dst_h + 1, np.int64),
        np.empty(max_h, np.float32),
        np.empty((max_h, dst_w * channels), np.float32),
        np.empty(dst_w * channels, np.float32),
    )


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _area_from_region(region, row0, col0, src_h, src_w, out, buffers):
    """ResizeArea_Invoker on the src_h x src_w crop at (row0, col0) of a transposed region,
    with the scratch arrays of `_region_buffers`."""
    channels = region.shape[0]
    dst_h, dst_w = out.shape[0], out.shape[1]
    x_src, x_weight, x_offsets, y_src, y_weight, y_offsets, acc, by_row, total = buffers
    _area_taps(src_w, dst_w, x_src, x_weight, x_offsets)
    _area_taps(src_h, dst_h, y_src, y_weight, y_offsets)
    # Horizontal pass, for every source row at once: buf = sum over x taps of S * alpha, one
    # output column at a time along the (contiguous) source rows, kept row-major with the
    # channels interleaved for the vertical pass, which then runs along whole output rows
    # (vectorised, all channels at once); every element still takes its taps in OpenCV's order.
    for c in range(channels):
        for dx in range(dst_w):
            k = x_offsets[dx]
            column = region[c, col0 + x_src[k], row0 : row0 + src_h]
            alpha = x_weight[k]
            for r in range(src_h):
                acc[r] = column[r] * alpha
            for k in range(x_offsets[dx] + 1, x_offsets[dx + 1]):
                column = region[c, col0 + x_src[k], row0 : row0 + src_h]
                alpha = x_weight[k]
                for r in range(src_h):
                    acc[r] = acc[r] + column[r] * alpha
            element = dx * channels + c
            for r in range(src_h):
                by_row[r, element] = acc[r]
    _vertical_pass(by_row, y_src, y_weight, y_offsets, out, total)


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _area_samples(image, tops, lefts, heights, widths, out):
    """All crops from one transposed copy of their bounding box (they overlap heavily), with one
    set of scratch arrays."""
    top, left, bottom, right = tops[0], lefts[0], tops[0] + heights[0], lefts[0] + widths[0]
    max_h, max_w = heights[0], widths[0]
    for i in range(1, tops.shape[0]):
        top, left = min(top, tops[i]), min(left, lefts[i])
        bottom, right = max(bottom, tops[i] + heights[i]), max(right, lefts[i] + widths[i])
        max_h, max_w = max(max_h, heights[i]), max(max_w, widths[i])
    region = _transposed_region(image, top, left, bottom - top, right - left)
    buffers = _region_buffers(region.shape[0], max_h, max_w, out.shape[1], out.shape[2])
    for i in range(tops.shape[0]):
        _area_from_region(
            region, tops[i] - top, lefts[i] - left, heights[i], widths[i], out[i], buffers
        )


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _padded_row_taps(x_src, x_weight, x_offsets, left, width, channels):
    """The horizontal taps of every output element of a row, padded to one count.

    Tap j of output element i (= dx * channels + c) reads element `offsets[j, i]` of the source
    row's span `[start, stop)` (flattened row, channels interleaved, columns clamped into the
    image) with weight `weight[j, i]`. Elements with fewer taps get weight 0 on a pixel of their
    own: the float32 sum then adds +0, which leaves it as it is (every sum is >= +0). The offsets
    are unsigned so that numba indexes with them without its negative-index test, which kept
    the gather loop 1.1-1.3x slower.
    """
    dst_w = x_offsets.shape[0] - 1
    taps = 0
    for dx in range(dst_w):
        taps = max(taps, x_offsets[dx + 1] - x_offsets[dx])
    index = np.empty((taps, dst_w * channels), np.int32)
    weight = np.zeros((taps, dst_w * channels), np.float32)
    for dx in range(dst_w):
        first, last = x_offsets[dx], x_offsets[dx + 1]
        for j in range(taps):
            k = min(first + j, last - 1)
            column = min(max(left + x_src[k], 0), width - 1)
            for c in range(channels):
                index[j, dx * channels + c] = column * channels + c
                if first + j < last:
                    weight[j, dx * channels + c] = x_weight[k]
    start, stop = index[0, 0], index[0, 0] + 1
    for j in range(taps):
        for i in range(dst_w * channels):
            start = min(start, index[j, i])
            stop = max(stop, index[j, i] + 1)
    offsets = np.empty((taps, dst_w * channels), np.uint32)  # unsigned: no wraparound test
    for j in range(taps):
        for i in range(dst_w * channels):
            offsets[j, i] = index[j, i] - start
    return offsets, weight, start, stop


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _gathered_row_sums(span, offsets, weight, target):
    """target[i] = sum over taps j of span[offsets[j, i]] * weight[j, i], taken in tap order.

    Up to four taps in the first pass over the row and two a pass after it: the running sum is
    stored once for the usual 2-4 taps, and every element still takes
    (((s0 a0 + s1 a1) + s2 a2) + s3 a3) + ..., OpenCV's sequence of float32 steps.
    """
    taps, row_width = offsets.shape
    o0, a0 = offsets[0], weight[0]
    if taps == 1:
        for i in range(row_width):
            target[i] = span[o0[i]] * a0[i]
        return
    o1, a1 = offsets[1], weight[1]
    if taps == 2:
        for i in range(row_width):
            target[i] = span[o0[i]] * a0[i] + span[o1[i]] * a1[i]
        return
    o2, a2 = offsets[2], weight[2]
    if taps == 3:
        for i in range(row_width):
            target[i] = (span[o0[i]] * a0[i] + span[o1[i]] * a1[i]) + span[o2[i]] * a2[i]
        return
    o3, a3 = offsets[3], weight[3]
    for i in range(row_width):
        pair = span[o0[i]] * a0[i] + span[o1[i]] * a1[i]
        target[i] = (pair + span[o2[i]] * a2[i]) + span[o3[i]] * a3[i]
    for j in range(4, taps - 1, 2):
        o0, a0, o1, a1 = offsets[j], weight[j], offsets[j + 1], weight[j + 1]
        for i in range(row_width):
            target[i] = (target[i] + span[o0[i]] * a0[i]) + span[o1[i]] * a1[i]
    if taps > 4 and taps % 2 == 1:
        o0, a0 = offsets[taps - 1], weight[taps - 1]
        for i in range(row_width):
            target[i] = target[i] + span[o0[i]] * a0[i]


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _rgb_taps(x_src, x_weight, x_offsets, taps):
    """The horizontal taps of a three-channel crop by output column: the flat offset of the
    first tap's red value in the crop's row (taps are consecutive columns, so tap j reads
    offset + 3 j) and the taps' weights, padded with 0 to `taps` (a padded tap reads a pixel
    of the row or of its zero tail: +0 added to a sum >= +0 leaves it as it is)."""
    dst_w = x_offsets.shape[0] - 1
    first_red = np.empty(dst_w, np.int64)
    weight = np.zeros((dst_w, taps), np.float32)
    for dx in range(dst_w):
        first, last = x_offsets[dx], x_offsets[dx + 1]
        first_red[dx] = 3 * x_src[first]
        for j in range(last - first):
            weight[dx, j] = x_weight[first + j]
    return first_red, weight


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy", inline="always")
def _rgb_row_sums(span, first_red, weight, target):
    """`_gathered_row_sums` for two to four taps of a three-channel row, by output column: the
    column's weights and first offset are loaded once for its three channels (a third of the
    loads of the element-wise gather), every element's sum taken in OpenCV's order."""
    taps = weight.shape[1]
    if taps == 2:
        for dx in range(first_red.shape[0]):
            b, w0, w1 = first_red[dx], weight[dx, 0], weight[dx, 1]
            target[3 * dx] = span[b] * w0 + span[b + 3] * w1
            target[3 * dx + 1] = span[b + 1] * w0 + span[b + 4] * w1
            target[3 * dx + 2] = span[b + 2] * w0 + span[b + 5] * w1
    elif taps == 3:
        for dx in range(first_red.shape[0]):
            b, w0, w1, w2 = first_red[dx], weight[dx, 0], weight[dx, 1], weight[dx, 2]
            target[3 * dx] = (span[b] * w0 + span[b + 3] * w1) + span[b + 6] * w2
            target[3 * dx + 1] = (span[b + 1] * w0 + span[b + 4] * w1) + span[b + 7] * w2
            target[3 * dx + 2] = (span[b + 2] * w0 + span[b + 5] * w1) + span[b + 8] * w2
    else:
        for dx in range(first_red.shape[0]):
            b, w0, w1 = first_red[dx], weight[dx, 0], weight[dx, 1]
            w2, w3 = weight[dx, 2], weight[dx, 3]
            for c in range(3):
                pair = span[b + c] * w0 + span[b + c + 3] * w1
                target[3 * dx + c] = (pair + span[b + c + 6] * w2) + span[b + c + 9] * w3


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _crop_taps(src_h, src_w, dst_h, dst_w):
    """Both axes' `_area_taps` of an src_h x src_w crop shrunk to dst_h x dst_w, and the largest
    horizontal tap count: (x taps, x weights, x offsets, y taps, y weights, y offsets, taps)."""
    x_src = np.empty(2 * src_w + 2, np.int64)
    x_weight = np.empty(2 * src_w + 2, np.float32)
    x_offsets = np.empty(dst_w + 1, np.int64)
    y_src = np.empty(2 * src_h + 2, np.int64)
    y_weight = np.empty(2 * src_h + 2, np.float32)
    y_offsets = np.empty(dst_h + 1, np.int64)
    _area_taps(src_w, dst_w, x_src, x_weight, x_offsets)
    _area_taps(src_h, dst_h, y_src, y_weight, y_offsets)
    taps = 0
    for dx in range(dst_w):
        taps = max(taps, x_offsets[dx + 1] - x_offsets[dx])
    return x_src, x_weight, x_offsets, y_src, y_weight, y_offsets, taps


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _area_crop_rgb(image, top, left, src_h, src_w, out):
    """One large crop of a three-channel image: ResizeArea_Invoker in the image's own (row, col,
    channel) layout, when every output column takes two to four horizontal taps (RGB search
    patches shrunk by less than ~3x); returns False, doing nothing, otherwise
    (`_area_crop_gathered` then takes it).

    Each source row's horizontal sums are computed once (OpenCV recomputes a row shared by two
    output rows, with the same result) from the row converted to float32 once, by output column
    (`_rgb_row_sums`); the vertical pass then runs vectorised along the row. numba does not
    vectorise the gathers; transposing rows into SIMD lanes to avoid them was measured slower
    (docs/benchmarks.md, ninth round).
    """
    height, width, channels = image.shape
    dst_h, dst_w = out.shape[0], out.shape[1]
    x_src, x_weight, x_offsets, y_src, y_weight, y_offsets, taps = _crop_taps(
        src_h, src_w, dst_h, dst_w
    )
    if channels != 3 or taps < 2 or taps > 4:
        return False
    row_width = dst_w * channels
    horizontal = np.empty((src_h, row_width), np.float32)
    flat = image.reshape(height, width * channels)
    first_red, weight = _rgb_taps(x_src, x_weight, x_offsets, taps)
    span = np.zeros(3 * (src_w + taps), np.float32)  # the crop's row, then a zero tail
    inside = left >= 0 and left + src_w <= width
    for r in range(src_h):
        pixels = flat[min(max(top + r, 0), height - 1)]
        if inside:
            row = pixels[3 * left : 3 * (left + src_w)]
            for q in range(3 * src_w):
                span[q] = np.float32(row[q])
        else:  # columns clamped into the image: the replicated border
            for q in range(src_w):
                column = 3 * min(max(left + q, 0), width - 1)
                for c in range(3):
                    span[3 * q + c] = np.float32(pixels[column + c])
        _rgb_row_sums(span, first_red, weight, horizontal[r])
    _vertical_pass(horizontal, y_src, y_weight, y_offsets, out, np.empty(row_width, np.float32))
    return True


@njit(cache=True, nogil=True, fastmath=False, error_model="numpy")
def _area_crop_gathered(image, top, left, src_h, src_w, out):
    """One large crop, any channel count and tap count (`_area_crop_rgb`'s other cases): up to
    four taps a pass over the whole output row (`_gathered_row_sums`), then the vertical pass."""
    height, width, channels = image.shape
    dst_h, dst_w = out.shape[0], out.shape[1]
    x_src, x_weight, x_offsets, y_src, y_weight, y_offsets, _ = _crop_taps(
        src_h, src_w, dst_h, dst_w
    )
    row_width = dst_w * channels
    horizontal = np.empty((src_h, row_width), np.float32)
    flat = image.reshape(height, width * channels)
    index, weight, start, stop = _padded_row_taps(x_src, x_weight, x_offsets, left, width, channels)
    span = np.empty(stop - start, np.float32)
    for r in range(src_h):
        pixels = flat[min(max(top + r, 0), height - 1)][start:stop]
        for q in range(stop - start):
            span[q] = np.float32(pixels[q])
        _gathered_row_sums(span, index, weight, horizontal[r])
    _vertical_pass(horizontal, y_src, y_weight, y_offsets, out, np.empty(row_width, np.float32))


def _kernel_pixels(image: np.ndarray, bounds: Callable[[], tuple[int, int, int, int]]):
    """(H, W, C) C-contiguous pixels covering the rows top..bottom and cols left..right that
    `bounds()` gives (clamped; asked only for a strided frame), and the offset of the returned
    array in the image. A strided frame (a view into a larger array) is cut to that region
    before the copy, so the cost never grows with the image."""
    pixels = image if image.ndim == 3 else image.reshape(*image.shape, 1)
    if pixels.flags.c_contiguous:
        return pixels, 0, 0
    top, left, bottom, right = bounds()
    height, width = pixels.shape[:2]
    row0 = min(max(int(top), 0), height - 1)
    col0 = min(max(int(left), 0), width - 1)
    row1 = max(min(int(bottom), height), row0 + 1)
    col1 = max(min(int(right), width), col0 + 1)
    return np.ascontiguousarray(pixels[row0:row1, col0:col1]), row0, col0


def area_resize_crop(
    image: np.ndarray, top: int, left: int, size_hw: tuple[int, int], out_hw: tuple[int, int]
) -> np.ndarray:
    """One crop of `image` (0-based top/left, border replicated) area-shrunk to `out_hw`, exactly
    as `cv2.resize(crop, INTER_AREA)`; `area_path_is_generic(size_hw, out_hw)` must hold."""
    rows, cols = int(size_hw[0]), int(size_hw[1])
    pixels, row0, col0 = _kernel_pixels(image, lambda: (top, left, top + rows, left + cols))
    out = np.empty((int(out_hw[0]), int(out_hw[1]), pixels.shape[2]), np.uint8)
    # Two kernels, not one with two paths: only the path a video needs is compiled.
    crop = (pixels, int(top) - row0, int(left) - col0, rows, cols, out)
    if not _area_crop_rgb(*crop):
        _area_crop_gathered(*crop)
    return out if image.ndim == 3 else out[..., 0]


def area_resize_crops(
    image: np.ndarray,
    tops: np.ndarray,
    lefts: np.ndarray,
    sizes_hw: np.ndarray,
    out_hw: tuple[int, int],
) -> np.ndarray:
    """Crops of `image` (0-based top/left, (rows, cols) sizes, border replicated) area-shrunk to
    `out_hw`, exactly as `cv2.resize(crop, INTER_AREA)`; every crop must satisfy
    `area_path_is_generic(size, out_hw)`. Returns uint8 (N, rows, cols[, C]) like the input."""
    count = len(tops)
    sizes = np.asarray(sizes_hw, dtype=np.int64).reshape(count, 2)
    tops = np.asarray(tops, dtype=np.int64)
    lefts = np.asarray(lefts, dtype=np.int64)
    pixels, row0, col0 = _kernel_pixels(
        image,
        lambda: (tops.min(), lefts.min(), (tops + sizes[:, 0]).max(), (lefts + sizes[:, 1]).max()),
    )
    out = np.empty((count, int(out_hw[0]), int(out_hw[1]), pixels.shape[2]), np.uint8)
    _area_samples(
        pixels,
        tops - row0,
        lefts - col0,
        np.ascontiguousarray(sizes[:, 0]),
        np.ascontiguousarray(sizes[:, 1]),
        out,
    )
    return out if image.ndim == 3 else out[..., 0]
