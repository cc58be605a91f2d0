"""In-plane rotation (autotrack+ switch `rotation_step`): patches sampled in the target's frame.

The target's in-plane angle is searched as SAMF searches scales (Li, Zhu: *A Scale Adaptive
Kernel Correlation Filter Tracker with Feature Integration*, ECCV 2014 workshops), over a pool
of angles around the current one, as the rotation pools of RAJSSC (Zhang et al., *Robust
Tracking via Joint Scale-Rotation Correlation Filter*, ICCV 2015 workshops) and LDES (Li et al.,
*Robust Estimation of Similarity Transformation for Visual Object Tracking*, AAAI 2019) do for
rotation: the patch is sampled in the rotated frame, so the filter stays aligned with the
target. Angles are in degrees, counter-clockwise as the image is displayed; an offset (row, col)
in the target's frame is `rotate_offset(offset, angle)` in the image.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from autotrack.tracker.plus.robust import apce
from autotrack.tracker.sampling import search_patch


def rotate_offset(offset_rowcol: np.ndarray, angle_deg: float) -> np.ndarray:
    """An offset (row, col) in the frame rotated by `angle_deg`, expressed in the image's."""
    radians = math.radians(angle_deg)
    cos, sin = math.cos(radians), math.sin(radians)
    row, col = float(offset_rowcol[0]), float(offset_rowcol[1])
    # x = col, y = row (down); a counter-clockwise turn on screen is clockwise in (x, y).
    return np.array([cos * row - sin * col, sin * row + cos * col])


def _inverse_map(angle_deg: float, source_centre_xy, output_centre_xy) -> np.ndarray:
    """2 x 3 map from an output pixel (x, y) to its source point (cv2.WARP_INVERSE_MAP)."""
    radians = math.radians(angle_deg)
    cos, sin = math.cos(radians), math.sin(radians)
    linear = np.array([[cos, sin], [-sin, cos]])  # (x, y) form of rotate_offset
    shift = np.asarray(source_centre_xy) - linear @ np.asarray(output_centre_xy)
    return np.hstack([linear, shift[:, None]])


def _warp(source: np.ndarray, matrix: np.ndarray, size_hw: tuple[int, int]) -> np.ndarray:
    """cv2.warpAffine of `source` by the inverse map `matrix` to `size_hw`, bilinear, edges
    replicated. A 3-channel image is warped as 4 channels, OpenCV's vectorised bilinear path
    (3 channels take its scalar one, 2x slower): the same values, as each channel is
    interpolated alone."""
    three_channels = source.ndim == 3 and source.shape[2] == 3
    if three_channels:
        source = cv2.cvtColor(source, cv2.COLOR_RGB2RGBA)
    warped = cv2.warpAffine(
        source,
        matrix,
        (int(size_hw[1]), int(size_hw[0])),
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_REPLICATE,
    )
    return cv2.cvtColor(warped, cv2.COLOR_RGBA2RGB) if three_channels else warped


def _footprint(
    matrix: np.ndarray, size_hw: tuple[int, int], image_hw: tuple[int, ...]
) -> tuple[slice, slice]:
    """The rows and columns of an image that a warp by the inverse map `matrix` to `size_hw`
    reads: the bound of the output's corners mapped into it, a pixel beyond for the bilinear
    weights, cut to the image (where the cut falls on the image's edge, the replicated edge
    is the image's own). Never empty: a view wholly beyond the image (a tracker's position may
    leave it) reads the image's nearest edge rows or columns, all that replication gives."""
    rows, cols = size_hw
    corners = np.array([[0.0, 0.0, cols - 1.0, cols - 1.0], [0.0, rows - 1.0, 0.0, rows - 1.0]])
    x, y = matrix[:, :2] @ corners + matrix[:, 2:]
    row_start = min(max(math.floor(y.min()) - 1, 0), image_hw[0] - 1)
    col_start = min(max(math.floor(x.min()) - 1, 0), image_hw[1] - 1)
    row_stop = max(min(math.ceil(y.max()) + 2, image_hw[0]), row_start + 1)
    col_stop = max(min(math.ceil(x.max()) + 2, image_hw[1]), col_start + 1)
    return slice(row_start, row_stop), slice(col_start, col_stop)


class TurnedSampler:
    """`sampling.search_patch` of one frame's search region in the frame turned by any angle.

    The search region is resampled once (area averaging, as the release) with a margin that
    covers its turned corners, on the first turned patch asked for, then turned at the patch's
    resolution per angle: one area resampling of ~2x the output's area per frame, shared by the
    current angle's patch and the trial angles', and one small warp per angle, instead of a
    warp at the image's resolution. The patch at angle 0 is `search_patch` itself.
    """

    def __init__(
        self,
        image: np.ndarray,
        position: tuple[float, float],
        region_size_hw: tuple[int, int],
        output_size_hw: tuple[int, int],
        sample=search_patch,
    ) -> None:
        self.image, self.position = image, position
        self.search_patch = sample  # `sampling.search_patch` or a backend's (the same pixels)
        self.region_size_hw = region_size_hw
        self.rows, self.cols = int(output_size_hw[0]), int(output_size_hw[1])
        margin = math.ceil(max(self.rows, self.cols) * (math.sqrt(2.0) - 1.0) / 2.0)
        self.big_hw = (self.rows + 2 * margin, self.cols + 2 * margin)
        self.big: np.ndarray | None = None

    def patch(self, angle_deg: float) -> np.ndarray:
        """The search patch in the frame turned by `angle_deg`."""
        if angle_deg == 0.0:
            output = (self.rows, self.cols)
            return self.search_patch(self.image, self.position, self.region_size_hw, output)
        big_hw = self.big_hw
        if self.big is None:
            factor = (big_hw[0] / self.rows, big_hw[1] / self.cols)
            region = self.region_size_hw
            bigger = (round(region[0] * factor[0]), round(region[1] * factor[1]))
            self.big = self.search_patch(self.image, self.position, bigger, big_hw)
        source_centre = ((big_hw[1] - 1) / 2.0, (big_hw[0] - 1) / 2.0)
        output_centre = ((self.cols - 1) / 2.0, (self.rows - 1) / 2.0)
        matrix = _inverse_map(angle_deg, source_centre, output_centre)
        return _warp(self.big, matrix, (self.rows, self.cols))


def rotated_search_patches(
    image: np.ndarray,
    position: tuple[float, float],
    region_size_hw: tuple[int, int],
    output_size_hw: tuple[int, int],
    angles_deg: tuple[float, ...],
) -> list[np.ndarray]:
    """`sampling.search_patch` in the frame turned by each angle (the same patch at 0)."""
    sampler = TurnedSampler(image, position, region_size_hw, output_size_hw)
    return [sampler.patch(angle) for angle in angles_deg]


def upright_view(
    image: np.ndarray, position: tuple[float, float], angle_deg: float, size_hw: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """A `size_hw` (rows, cols) view of the image around the 1-based `position`, rotated so the
    target is upright, and the position's 1-based (row, col) in it: what the scale filter
    samples. The samples are axis-aligned in the view, so it need only hold the largest."""
    rows, cols = int(size_hw[0]), int(size_hw[1])
    centre = (rows // 2, cols // 2)  # 0-based index of `position`, as crop_replicate centres
    # Turned about the point half a pixel past the position's pixel: the centre of an even-sized
    # crop around it (sampling.crop_replicate), about which rotated_search_patches turns too.
    source_centre = (float(position[1]) - 0.5, float(position[0]) - 0.5)
    matrix = _inverse_map(angle_deg, source_centre, (centre[1] + 0.5, centre[0] + 0.5))
    # Warped from the part of the image it reads (its shift in the map is exact: an integer).
    row_span, col_span = _footprint(matrix, (rows, cols), image.shape[:2])
    matrix[:, 2] -= (col_span.start, row_span.start)
    view = _warp(image[row_span, col_span], matrix, (rows, cols))
    return view, np.array([centre[0] + 1.0, centre[1] + 1.0])


def candidate_angles(angle_deg: float, step_deg: float) -> tuple[float, ...]:
    """The current angle first, then one step either way (the pool searched each frame); the
    current angle alone when the step is 0."""
    if not step_deg:
        return (angle_deg,)
    return (angle_deg, angle_deg + step_deg, angle_deg - step_deg)


def turn_wins(turned: tuple, current: tuple, margin: float) -> bool:
    """Whether a turned sample's detection, (response, (row, col, peak)), beats the current
    angle's: a peak higher by `margin` and a response at least as sharp (APCE, robust.apce).

    A turn of the whole target makes the turned sample match the filter as the target did
    before the turn: a higher peak over sidelobes no higher, so a sharper response. A turned
    sample whose peak rises with its sidelobes (APCE not higher) matches more of everything in
    the patch, background or another part of the target, rather than the target turned back
    into the filter's frame.
    """
    turned_response, (_, _, turned_peak) = turned
    current_response, (_, _, current_peak) = current
    if turned_peak <= current_peak * (1.0 + margin):
        return False
    return apce(turned_response) >= apce(current_response)


def wrapped(angle_deg: float) -> float:
    """The same angle in (-180, 180]."""
    turned = math.fmod(angle_deg + 180.0, 360.0)
    return turned - 180.0 if turned > 0 else turned + 180.0


def bounding_size(size_hw: np.ndarray, angle_deg: float) -> np.ndarray:
    """(height, width) of the axis-aligned box reported for a target of `size_hw` turned by
    `angle_deg`: the bound of the ellipse inscribed in the turned box.

    A target fills about the ellipse of its box (a body, a vehicle), not its corners; the bound
    of the turned rectangle over-states a target turned by 45 degrees by up to 41 % a side,
    the ellipse's bound is exact for an elliptical target, equal to `size_hw` at 0 and swaps
    height and width at 90 degrees.
    """
    radians = math.radians(angle_deg)
    cos, sin = abs(math.cos(radians)), abs(math.sin(radians))
    height, width = float(size_hw[0]), float(size_hw[1])
    return np.array([math.hypot(height * cos, width * sin), math.hypot(width * cos, height * sin)])
