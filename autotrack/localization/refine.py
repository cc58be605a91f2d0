"""Sub-pixel landmark points on top of the tracker's boxes.

A correlation filter places its box on a cell grid and re-learns the target every frame, so its
box centre wanders a pixel or two around the landmark. The landmarks are planar, so each one's
first-frame appearance maps onto every later view by a homography: we align that first-frame
template to the current frame with ECC (Evangelidis & Psarakis 2008, `cv2.findTransformECC`,
invariant to gain and offset changes of the lighting), starting from the previous frame's
homography moved by the tracker's motion, and take the image of the template's centre. Aligning
to the *first* frame's appearance, not the previous frame's, means the point cannot drift.

The refined point replaces the box centre only when it is consistent with the tracker: the
alignment converged with a high correlation, stayed near the tracker's box and kept a plausible
scale; otherwise the box centre is used and the next frame starts again from the tracker.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import cv2
import numpy as np

Box = tuple[float, float, float, float]


@dataclass(frozen=True)
class RefineParams:
    """Settings of the template alignment that sharpens each landmark's image point."""

    min_correlation: float = 0.7
    """Smallest ECC correlation coefficient (0-1) at which the refined point is used."""
    max_offset_fraction: float = 0.2
    """The refined point must lie within this fraction of the box size (the larger side) of the
    tracker's box centre, else the tracker and the alignment disagree and the box centre is used."""
    min_offset_px: float = 4.0
    """Floor of that distance bound for small boxes (pixels)."""
    max_scale_ratio: float = 1.3
    """The alignment's scale may differ from the tracker's box scale by at most this factor."""
    search_margin: float = 0.3
    """The image crop the template is aligned in extends this fraction of the box size beyond the
    predicted landmark region on every side."""
    iterations: int = 40
    """Largest number of ECC iterations per landmark and frame."""
    epsilon: float = 1e-4
    """ECC stops when the warp changes by less than this between iterations."""
    blur_size: int = 3
    """Gaussian blur (odd kernel size, pixels) ECC applies to both images; 1 disables."""
    fallback_weight: float = 0.05
    """Weight in the pose solve of a landmark whose refined point was rejected (its box centre
    is used), while at least three others are refined: box centres are a few pixels off where
    refined points are a few tenths, (0.2 / 1)^2 ~ 0.05."""
    max_stale_frames: int = 5
    """After this many frames without an accepted alignment the homography is rebuilt from the
    tracker's box instead of the last accepted one."""
    template_fraction: float = 0.7
    """The template ECC aligns is this central fraction (of each side) of the first box. The box
    bounds the landmark's projection, so its border holds background at another depth that does
    not follow the landmark's homography: the centre part converges in fewer, cheaper iterations
    and no less accurately (1.0: the whole box)."""


@dataclass(frozen=True)
class RefinedPoint:
    """One landmark's point for one frame."""

    point: tuple[float, float]
    """The image point given to the pose solver (u, v), 0-based pixels."""
    refined: bool
    """True when the template alignment was accepted, False when the box centre is used."""
    correlation: float
    """ECC correlation of the alignment (NaN when it did not run or failed)."""
    offset_px: float
    """Distance from the tracker's box centre to the aligned point (NaN when not aligned)."""
    reason: str = ""
    """Why the alignment was rejected (empty when accepted)."""


def box_centre(box: Box) -> tuple[float, float]:
    """Centre (u, v) of an (x, y, w, h) box."""
    x, y, w, h = box
    return (x + w / 2.0, y + h / 2.0)


def map_point(homography: np.ndarray, point: tuple[float, float]) -> tuple[float, float]:
    """Image of `point` under a 3x3 homography."""
    u, v, w = homography @ np.array([point[0], point[1], 1.0])
    return (float(u / w), float(v / w))


def homography_scale(homography: np.ndarray, point: tuple[float, float]) -> float:
    """Local linear scale of a homography at `point`: sqrt |det J|."""
    x, y = point
    w = homography[2, 0] * x + homography[2, 1] * y + homography[2, 2]
    u, v = map_point(homography, point)
    jacobian = (
        np.array(
            [
                [homography[0, 0] - u * homography[2, 0], homography[0, 1] - u * homography[2, 1]],
                [homography[1, 0] - v * homography[2, 0], homography[1, 1] - v * homography[2, 1]],
            ]
        )
        / w
    )
    return math.sqrt(abs(float(np.linalg.det(jacobian))))


def about_point(point: tuple[float, float], scale: float, shift: tuple[float, float]) -> np.ndarray:
    """3x3 map scaling by `scale` about `point`, then translating by `shift`."""
    u, v = point
    return np.array(
        [
            [scale, 0.0, (1.0 - scale) * u + shift[0]],
            [0.0, scale, (1.0 - scale) * v + shift[1]],
            [0.0, 0.0, 1.0],
        ]
    )


def to_grey(frame: np.ndarray) -> np.ndarray:
    """float32 grey image of an RGB or grey uint8 frame (or of a crop of one: the conversion is
    per pixel, so a crop's grey is the same crop of the frame's grey)."""
    grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)
    return grey.astype(np.float32)


def pixel_region(box: Box, shape: tuple[int, ...]) -> tuple[int, int, int, int] | None:
    """Whole-pixel region (x0, y0, x1, y1) of an (x, y, w, h) box clipped to an image of `shape`;
    None when smaller than 8 x 8 pixels."""
    x, y, w, h = box
    x0, y0 = max(int(round(x)), 0), max(int(round(y)), 0)
    x1, y1 = min(int(round(x + w)), shape[1]), min(int(round(y + h)), shape[0])
    return (x0, y0, x1, y1) if x1 - x0 >= 8 and y1 - y0 >= 8 else None


@dataclass
class _Template:
    image: np.ndarray
    """First-frame grey patch of the whole first box (float32; re-acquisition matches it)."""
    centre: tuple[float, float]
    """The landmark's point in `image` coordinates (the first box's centre)."""
    aligned: np.ndarray
    """The part of `image` ECC aligns (`RefineParams.template_fraction`)."""
    aligned_centre: tuple[float, float]
    """The landmark's point in `aligned` coordinates."""
    size: float
    """Larger side of the first box (pixels)."""
    homography: np.ndarray
    """Last accepted `aligned` -> image homography."""
    last_box: Box
    """The tracker's box of the frame the homography was accepted on."""
    stale: int = 0
    """Frames since the last accepted alignment."""


def align_template(
    template: np.ndarray,
    frame: np.ndarray,
    start: np.ndarray,
    params: RefineParams,
) -> tuple[float, np.ndarray] | None:
    """ECC homography template -> frame (RGB or grey) from `start`, aligned inside a crop around
    the predicted region (only the crop is converted to grey). Returns (correlation, homography
    in frame coordinates) or None if ECC fails."""
    height, width = template.shape
    corners = np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]], float)
    projected = cv2.perspectiveTransform(corners.reshape(-1, 1, 2), start).reshape(-1, 2)
    span = float(np.max(projected.max(axis=0) - projected.min(axis=0)))
    margin = params.search_margin * span + 4.0
    x0 = max(int(math.floor(projected[:, 0].min() - margin)), 0)
    y0 = max(int(math.floor(projected[:, 1].min() - margin)), 0)
    x1 = min(int(math.ceil(projected[:, 0].max() + margin)) + 1, frame.shape[1])
    y1 = min(int(math.ceil(projected[:, 1].max() + margin)) + 1, frame.shape[0])
    if x1 - x0 < 8 or y1 - y0 < 8:
        return None
    crop = to_grey(frame[y0:y1, x0:x1])
    to_crop = about_point((0.0, 0.0), 1.0, (-x0, -y0))
    warp = (to_crop @ start).astype(np.float32)
    warp /= warp[2, 2]
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, params.iterations, params.epsilon)
    try:
        correlation, warp = cv2.findTransformECC(
            template, crop, warp, cv2.MOTION_HOMOGRAPHY, criteria, None, params.blur_size
        )
    except cv2.error:  # no convergence or a singular warp
        return None
    return float(correlation), about_point((0.0, 0.0), 1.0, (x0, y0)) @ warp.astype(np.float64)


@dataclass
class PointRefiner:
    """Per-landmark template alignment; `init` on the first frame, `refine` on every later one."""

    params: RefineParams = field(default_factory=RefineParams)
    _templates: dict[str, _Template] = field(default_factory=dict, init=False, repr=False)

    def init(self, frame: np.ndarray, boxes: Mapping[str, Box]) -> dict[str, RefinedPoint]:
        """Store each landmark's first-frame appearance; returns the box centres."""
        return {k: self.set_template(k, frame, box) for k, box in boxes.items()}

    def set_template(self, landmark_id: str, frame: np.ndarray, box: Box) -> RefinedPoint:
        """(Re)take a landmark's template from `box` of an RGB or grey frame."""
        centre = box_centre(box)
        whole = pixel_region(box, frame.shape)
        if whole is None:
            self._templates.pop(landmark_id, None)
            return RefinedPoint(centre, False, math.nan, math.nan, "first frame")
        x, y, w, h = box
        fraction = self.params.template_fraction
        inner = (x + w * (1 - fraction) / 2, y + h * (1 - fraction) / 2, w * fraction, h * fraction)
        x0, y0, x1, y1 = whole
        ax0, ay0, ax1, ay1 = pixel_region(inner, frame.shape) or whole
        image = to_grey(frame[y0:y1, x0:x1])
        self._templates[landmark_id] = _Template(
            image=image,
            centre=(centre[0] - x0, centre[1] - y0),
            aligned=image[ay0 - y0 : ay1 - y0, ax0 - x0 : ax1 - x0].copy(),
            aligned_centre=(centre[0] - ax0, centre[1] - ay0),
            size=float(max(w, h)),
            homography=np.array([[1.0, 0.0, ax0], [0.0, 1.0, ay0], [0.0, 0.0, 1.0]]),
            last_box=tuple(box),
        )
        return RefinedPoint(centre, False, math.nan, math.nan, "first frame")

    def has_template(self, landmark_id: str) -> bool:
        """True when `landmark_id` has a template to align."""
        return landmark_id in self._templates

    def template_of(self, landmark_id: str) -> tuple[np.ndarray, tuple[float, float]]:
        """A landmark's grey template and its centre in template coordinates."""
        template = self._templates[landmark_id]
        return template.image, template.centre

    def restart(self, landmark_id: str) -> None:
        """Forget a landmark's last alignment (its tracker was restarted): the next frame starts
        from the tracker's box."""
        template = self._templates.get(landmark_id)
        if template is not None:
            template.stale = self.params.max_stale_frames + 1

    def refine(self, frame: np.ndarray, boxes: Mapping[str, Box]) -> dict[str, RefinedPoint]:
        """Refined (or fallback) points of the landmarks whose tracked boxes are given."""
        return {k: self.refine_one(frame, k, box) for k, box in boxes.items()}

    def refine_one(self, frame: np.ndarray, landmark_id: str, box: Box) -> RefinedPoint:
        """One landmark: align its template near the tracked `box` of an RGB or grey frame."""
        params = self.params
        centre = box_centre(box)
        if not all(math.isfinite(v) for v in box):
            return RefinedPoint(centre, False, math.nan, math.nan, "no box")
        template = self._templates.get(landmark_id)
        if template is None:
            return RefinedPoint(centre, False, math.nan, math.nan, "no template")
        start = self._start(template, box)
        aligned = align_template(template.aligned, frame, start, params)
        template.stale += 1
        if aligned is None:
            return RefinedPoint(centre, False, math.nan, math.nan, "alignment failed")
        correlation, homography = aligned
        point = map_point(homography, template.aligned_centre)
        offset = math.dist(point, centre)
        box_scale = max(box[2], box[3]) / template.size
        scale_ratio = homography_scale(homography, template.aligned_centre) / box_scale
        limit = max(params.max_offset_fraction * max(box[2], box[3]), params.min_offset_px)
        reason = ""
        if not correlation >= params.min_correlation:
            reason = f"correlation {correlation:.2f} < {params.min_correlation:g}"
        elif offset > limit:
            reason = f"{offset:.1f} px from the box centre (limit {limit:.1f})"
        elif not 1.0 / params.max_scale_ratio <= scale_ratio <= params.max_scale_ratio:
            reason = f"scale {scale_ratio:.2f} x the tracker's"
        if reason:
            return RefinedPoint(centre, False, correlation, offset, reason)
        template.homography = homography
        template.last_box = tuple(box)
        template.stale = 0
        return RefinedPoint(point, True, correlation, offset)

    def _start(self, template: _Template, box: Box) -> np.ndarray:
        """Initial homography: the last accepted one moved and scaled as the tracker's box moved,
        or, when stale, the template placed on the tracker's box."""
        centre = box_centre(box)
        if template.stale > self.params.max_stale_frames:
            scale = max(box[2], box[3]) / template.size
            cx, cy = template.aligned_centre
            return np.array(
                [
                    [scale, 0.0, centre[0] - scale * cx],
                    [0.0, scale, centre[1] - scale * cy],
                    [0.0, 0.0, 1.0],
                ]
            )
        previous = template.last_box
        before = box_centre(previous)
        scale = max(box[2], box[3]) / max(previous[2], previous[3])
        point = map_point(template.homography, template.aligned_centre)
        motion = (centre[0] - before[0], centre[1] - before[1])
        return about_point(point, scale, motion) @ template.homography


def fallback_weights(
    refined: Mapping[str, bool], params: RefineParams | None
) -> dict[str, float] | None:
    """Solver weights when refinement is on: a landmark whose refined point was rejected (its
    box centre is pixels off) counts `params.fallback_weight` while three others are refined."""
    if params is None or sum(refined.values()) < 3:
        return None
    return {i: 1.0 if ok else params.fallback_weight for i, ok in refined.items()}
