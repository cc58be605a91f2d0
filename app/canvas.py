"""Pictures for the browser: the letterboxed frame, boxes, peaks and colour-mapped maps.

The 3-D canvas stretches its background image to the canvas, so the frame is padded (never
scaled unevenly) to the canvas aspect on the server. A rect-select then maps back to frame
pixels with one scale and one offset, exactly. Drawing here is display only: the tracker's
numbers are never changed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from autotrack.result import TrackResult

Box = tuple[float, float, float, float]

TARGET_COLOURS: tuple[tuple[int, int, int], ...] = (
    (64, 200, 255),
    (255, 200, 0),
    (120, 255, 80),
    (255, 80, 255),
    (0, 255, 200),
    (180, 120, 255),
    (255, 150, 60),
)
"""RGB colour of target number i (cycled): none red, which marks an aberrant frame (the outer
box, the charts' dots) and an untrusted pose."""
ABERRANT = (255, 0, 0)
"""Colour of an aberrant frame's outer box."""


TRUTH = (255, 255, 255)
"""Colour of the ground-truth box."""


def target_colour(index: int) -> tuple[int, int, int]:
    """RGB colour of the target at position `index` in the target list."""
    return TARGET_COLOURS[index % len(TARGET_COLOURS)]


@dataclass(frozen=True)
class Letterbox:
    """How a frame sits in a padded image of the canvas's aspect ratio (frame pixels)."""

    frame_width: int
    frame_height: int
    padded_width: int
    """Width of the padded image in frame pixels (>= frame_width)."""
    padded_height: int
    """Height of the padded image in frame pixels (>= frame_height)."""
    offset_x: int
    """Frame column 0 starts this many pixels into the padded image."""
    offset_y: int
    """Frame row 0 starts this many pixels into the padded image."""

    def screen_to_frame(self, u: float, v: float) -> tuple[float, float]:
        """Canvas fractions (0..1, top-left origin) to frame pixel coordinates."""
        return (u * self.padded_width - self.offset_x, v * self.padded_height - self.offset_y)

    def frame_to_screen(self, x: float, y: float) -> tuple[float, float]:
        """Frame pixel coordinates to canvas fractions."""
        return ((x + self.offset_x) / self.padded_width, (y + self.offset_y) / self.padded_height)

    def rect_inside(self, screen_min: tuple[float, float], screen_max: tuple[float, float]) -> bool:
        """Whether a rect-select (canvas fractions) lies within the frame (to a pixel)."""
        x0, y0 = self.screen_to_frame(*screen_min)
        x1, y1 = self.screen_to_frame(*screen_max)
        width, height = self.frame_width + 1.0, self.frame_height + 1.0
        return all(-1.0 <= x <= width for x in (x0, x1)) and all(
            -1.0 <= y <= height for y in (y0, y1)
        )

    def rect_to_box(
        self, screen_min: tuple[float, float], screen_max: tuple[float, float]
    ) -> Box | None:
        """A rect-select (canvas fractions) as a frame box clipped to the frame, or None if the
        rectangle misses the frame or is thinner than 2 pixels after clipping."""
        x0, y0 = self.screen_to_frame(*screen_min)
        x1, y1 = self.screen_to_frame(*screen_max)
        left, right = sorted((x0, x1))
        top, bottom = sorted((y0, y1))
        left, top = max(left, 0.0), max(top, 0.0)
        right, bottom = min(right, float(self.frame_width)), min(bottom, float(self.frame_height))
        if right - left < 2.0 or bottom - top < 2.0:
            return None
        return (left, top, right - left, bottom - top)


def fit_letterbox(frame_size: tuple[int, int], canvas_size: tuple[int, int]) -> Letterbox:
    """The smallest padding of a (w, h) frame to the aspect of a (w, h) canvas."""
    frame_width, frame_height = frame_size
    canvas_width, canvas_height = canvas_size
    if min(frame_width, frame_height, canvas_width, canvas_height) <= 0:
        raise ValueError("frame and canvas sizes must be positive")
    canvas_aspect = canvas_width / canvas_height
    if canvas_aspect >= frame_width / frame_height:
        padded_width = max(frame_width, round(frame_height * canvas_aspect))
        padded_height = frame_height
    else:
        padded_width = frame_width
        padded_height = max(frame_height, round(frame_width / canvas_aspect))
    return Letterbox(
        frame_width=frame_width,
        frame_height=frame_height,
        padded_width=padded_width,
        padded_height=padded_height,
        offset_x=(padded_width - frame_width) // 2,
        offset_y=(padded_height - frame_height) // 2,
    )


def letterbox_image(image: np.ndarray, letterbox: Letterbox, max_width: int) -> np.ndarray:
    """The RGB frame padded with black to the letterbox, scaled down to at most `max_width`
    wide and `max_width` high. Only the output is allocated (the frame is scaled, then padded):
    a canvas of extreme aspect (1x1500) costs no more than a square one."""
    scale = min(1.0, max_width / letterbox.padded_width, max_width / letterbox.padded_height)
    width = max(1, round(letterbox.padded_width * scale))
    height = max(1, round(letterbox.padded_height * scale))
    rgb = as_rgb(image)
    if scale < 1.0:
        frame_width = min(width, max(1, round(letterbox.frame_width * scale)))
        frame_height = min(height, max(1, round(letterbox.frame_height * scale)))
        rgb = cv2.resize(rgb, (frame_width, frame_height), interpolation=cv2.INTER_AREA)
    padded = np.zeros((height, width, 3), dtype=np.uint8)
    top = min(round(letterbox.offset_y * scale), height - rgb.shape[0])
    left = min(round(letterbox.offset_x * scale), width - rgb.shape[1])
    padded[top : top + rgb.shape[0], left : left + rgb.shape[1]] = rgb
    return padded


def as_rgb(image: np.ndarray) -> np.ndarray:
    """An HxWx3 uint8 view or copy of a grey or RGB frame."""
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    return image


Limits = tuple[float, float]

ROBUST_PERCENTILES = (2.0, 98.0)
"""The local-variation colour scale spans these percentiles of the map's finite values: the
variation divides by the previous response, so a few near-zero divisors would otherwise set
the scale and leave one hot pixel."""


def robust_limits(values: np.ndarray) -> Limits | None:
    """(low, high) percentiles ROBUST_PERCENTILES of the finite values (None: none finite)."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return None
    low, high = np.percentile(finite, ROBUST_PERCENTILES)
    return (float(low), float(high))


def log_limits(values: np.ndarray) -> Limits | None:
    """(min, max) of log10 of the positive finite values (the ASR weights span decades)."""
    positive = values[np.isfinite(values) & (values > 0)]
    if positive.size == 0:
        return None
    return (float(np.log10(positive.min())), float(np.log10(positive.max())))


def normalised(values: np.ndarray, limits: Limits | None = None) -> np.ndarray:
    """A float map scaled to 0..1 between `limits` (default its min and max) and clipped (all
    zeros when flat; NaN and inf count as the low end)."""
    data = values.astype(np.float32)
    finite = np.isfinite(data)
    if limits is None:
        if not finite.any():
            return np.zeros(data.shape, np.float32)
        limits = (float(data[finite].min()), float(data[finite].max()))
    low, high = limits
    if not high > low:
        return np.zeros(data.shape, np.float32)
    scaled = (np.where(finite, data, low) - low) / (high - low)
    return np.clip(scaled, 0.0, 1.0).astype(np.float32)


def colour_map(values: np.ndarray, limits: Limits | None = None) -> np.ndarray:
    """A float map as an RGB image (scaled to `limits`, default min-max; OpenCV's JET)."""
    scaled = np.round(normalised(values, limits) * 255.0).astype(np.uint8)
    return cv2.cvtColor(cv2.applyColorMap(scaled, cv2.COLORMAP_JET), cv2.COLOR_BGR2RGB)


def _label(image: np.ndarray, text: str, origin: tuple[int, int], colour=(0, 0, 0)) -> None:
    cv2.putText(image, text, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.38, colour, 1, cv2.LINE_AA)


def legend_bar(width: int, limits: Limits | None, unit: str = "") -> np.ndarray:
    """A white strip with the JET colour bar and its low and high values (`unit` after them)."""
    strip = np.full((26, width, 3), 255, np.uint8)
    ramp = np.linspace(0.0, 1.0, width - 8, dtype=np.float32)[None, :].repeat(8, axis=0)
    strip[2:10, 4 : width - 4] = colour_map(ramp, (0.0, 1.0))
    if limits is not None:
        _label(strip, f"{limits[0]:.3g}{unit}", (4, 22))
        high = f"{limits[1]:.3g}{unit}"
        _label(strip, high, (width - 4 - 7 * len(high), 22))
    return strip


MAP_TILE = 160
"""Side of one map tile in a target's map panel (pixels)."""


def map_tile(
    values: np.ndarray | None, title: str, scale: str = "minmax", size: int = MAP_TILE
) -> np.ndarray:
    """A titled, colour-mapped map with its legend. `scale`: 'minmax', 'robust' (the
    ROBUST_PERCENTILES) or 'log' (log10, legend in decades). Grey when `values` is None."""
    header = np.full((18, size, 3), 255, np.uint8)
    _label(header, title, (3, 13))
    if values is None:
        body, limits, unit = np.full((size, size, 3), 64, np.uint8), None, ""
    else:
        data = values.astype(np.float32)
        if scale == "log":
            with np.errstate(divide="ignore", invalid="ignore"):
                data = np.log10(np.where(data > 0, data, np.nan))
            limits, unit = log_limits(values), " (log10)"
        elif scale == "robust":
            limits, unit = robust_limits(data), ""
        else:
            finite = data[np.isfinite(data)]
            limits = None if finite.size == 0 else (float(finite.min()), float(finite.max()))
            unit = ""
        body = cv2.resize(colour_map(data, limits), (size, size), interpolation=cv2.INTER_NEAREST)
    return np.concatenate([header, body, legend_bar(size, limits, unit)], axis=0)


def map_panel(values: np.ndarray | None, size: int = MAP_TILE) -> np.ndarray:
    """A colour-mapped map (min-max) enlarged to `size` pixels square (grey if None)."""
    if values is None:
        return np.full((size, size, 3), 64, dtype=np.uint8)
    return cv2.resize(colour_map(values), (size, size), interpolation=cv2.INTER_NEAREST)


def peak_position(result: TrackResult) -> tuple[float, float] | None:
    """Where the response map's maximum lies in the frame (pixels), or None without a map.

    The map covers `search_box` cell by cell, so cell (i, j) sits at the search box's origin
    plus (j + 0.5, i + 0.5) cell sizes.
    """
    if result.response_map is None:
        return None
    rows, cols = result.response_map.shape[:2]
    row, col = np.unravel_index(int(np.nanargmax(result.response_map)), (rows, cols))
    sx, sy, sw, sh = result.search_box
    return (sx + (col + 0.5) * sw / cols, sy + (row + 0.5) * sh / rows)


def target_part(values: np.ndarray, search_box: Box, box: Box) -> tuple[np.ndarray, Box]:
    """The cells of a map (covering `search_box`) that lie under the target's `box`, and the
    image region they cover: where ASR sets the spatial weights from the local variation."""
    rows, cols = values.shape[:2]
    sx, sy, sw, sh = search_box
    x, y, w, h = box
    c0 = int(np.clip(np.floor((x - sx) / sw * cols), 0, cols - 1))
    c1 = int(np.clip(np.ceil((x + w - sx) / sw * cols), c0 + 1, cols))
    r0 = int(np.clip(np.floor((y - sy) / sh * rows), 0, rows - 1))
    r1 = int(np.clip(np.ceil((y + h - sy) / sh * rows), r0 + 1, rows))
    region = (
        sx + c0 * sw / cols,
        sy + r0 * sh / rows,
        (c1 - c0) * sw / cols,
        (r1 - r0) * sh / rows,
    )
    return values[r0:r1, c0:c1], region


def blend_map(
    image: np.ndarray,
    values: np.ndarray,
    region: Box,
    opacity: float,
    limits: Limits | None = None,
) -> None:
    """Blend a colour-mapped map (scaled to `limits`, default min-max) over `region` (x, y, w,
    h) of `image`, in place.

    Each pixel's opacity grows with the map's value, so the high responses stand out and the
    low ones leave the frame visible.
    """
    x, y, w, h = region
    left, top = round(x), round(y)
    width, height = max(1, round(w)), max(1, round(h))
    size = (width, height)
    coloured = cv2.resize(colour_map(values, limits), size, interpolation=cv2.INTER_LINEAR)
    weight = cv2.resize(normalised(values, limits), size, interpolation=cv2.INTER_LINEAR) * opacity
    img_h, img_w = image.shape[:2]
    x0, y0 = max(left, 0), max(top, 0)
    x1, y1 = min(left + width, img_w), min(top + height, img_h)
    if x1 <= x0 or y1 <= y0:
        return
    patch = np.ascontiguousarray(coloured[y0 - top : y1 - top, x0 - left : x1 - left])
    alpha = np.ascontiguousarray(weight[y0 - top : y1 - top, x0 - left : x1 - left])
    target = np.ascontiguousarray(image[y0:y1, x0:x1])
    image[y0:y1, x0:x1] = cv2.blendLinear(target, patch, 1.0 - alpha, alpha)


@dataclass(frozen=True)
class TargetDrawing:
    """What to draw for one target on one frame."""

    label: str
    colour: tuple[int, int, int]
    box: Box
    result: TrackResult | None
    """The tracker's result for this frame (None for a freshly drawn, untracked box)."""
    selected: bool = False
    previous_response: np.ndarray | None = None
    """The target's response map on the frame before (for the map panels)."""
    weights: np.ndarray | None = None
    """The ASR spatial weights of the target's filter now (for the map panels)."""
    weights_frame: int | None = None
    """The frame the filter was last trained on, with `weights` (0-based)."""


def draw_overlays(
    frame: np.ndarray,
    targets: Sequence[TargetDrawing],
    map_kind: str,
    max_width: int | None = None,
    map_opacity: float = 0.7,
    truth_boxes: Sequence[tuple[Box, str]] = (),
) -> np.ndarray:
    """The frame, scaled down to at most `max_width` pixels, with each target's box, label and
    response peak drawn, and its response map ('response') or local variation map
    ('local_variation') blended over its search region, and `truth_boxes` (the ground truth,
    (box, label) each) in white. An aberrant frame gets a red outer box and the word ABERRANT. The input frame is not
    modified."""
    rgb = as_rgb(frame)
    scale = 1.0
    if max_width is not None and rgb.shape[1] > max_width:
        scale = max_width / rgb.shape[1]
        canvas = scaled_for_display(rgb, max_width)
    else:
        canvas = np.ascontiguousarray(rgb).copy()

    def scaled(box: Box) -> Box:
        return (box[0] * scale, box[1] * scale, box[2] * scale, box[3] * scale)

    line = max(1, round(canvas.shape[1] / 640))
    if map_kind in ("response", "local_variation", "local_variation_target"):
        _blend_maps(canvas, targets, map_kind, scale, map_opacity)
    for truth_box, truth_label in truth_boxes:
        _truth_on(canvas, scaled(truth_box), line, truth_label)
    for target in targets:
        x, y, w, h = scaled(target.box)
        top_left = (round(x), round(y))
        bottom_right = (round(x + w), round(y + h))
        thickness = line * (2 if target.selected else 1) + 1
        cv2.rectangle(canvas, top_left, bottom_right, target.colour, thickness, cv2.LINE_AA)
        result = target.result
        text = target.label
        if result is not None and result.aberrant:
            text += " ABERRANT"
            cv2.rectangle(
                canvas,
                (top_left[0] - 3 * line, top_left[1] - 3 * line),
                (bottom_right[0] + 3 * line, bottom_right[1] + 3 * line),
                ABERRANT,
                line,
                cv2.LINE_4,
            )
        peak = None if result is None else peak_position(result)
        if peak is not None:
            cv2.drawMarker(
                canvas,
                (round(peak[0] * scale), round(peak[1] * scale)),
                (255, 255, 255),
                cv2.MARKER_CROSS,
                8 * line,
                line + 1,
            )
        cv2.putText(
            canvas,
            text,
            (top_left[0], max(12 * line, top_left[1] - 4 * line)),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.45 * line,
            target.colour,
            line,
            cv2.LINE_AA,
        )
    return canvas


def _blend_maps(
    canvas: np.ndarray,
    targets: Sequence[TargetDrawing],
    map_kind: str,
    scale: float,
    opacity: float,
) -> None:
    """Each target's map blended over its search region (or its box, for the local variation
    over the target region), with the local variation's colour scale top right; in place."""

    def scaled(box: Box) -> Box:
        return (box[0] * scale, box[1] * scale, box[2] * scale, box[3] * scale)

    legend: Limits | None = None
    for target in targets:
        result = target.result
        if result is None:
            continue
        values = result.response_map if map_kind == "response" else result.local_variation
        if values is None:
            continue
        region = result.search_box
        if map_kind == "local_variation_target":  # only where ASR uses it
            values, region = target_part(values, result.search_box, target.box)
        limits = robust_limits(values)  # a few extreme values do not wash the rest out
        if limits is None or not limits[1] > limits[0]:  # a spike on a flat map: min-max
            finite = values[np.isfinite(values)]
            limits = (float(finite.min()), float(finite.max())) if finite.size else None
        blend_map(canvas, values, scaled(region), opacity, limits)
        legend = limits or legend
    if legend is not None:
        _legend_on(canvas, legend, "response" if map_kind == "response" else "local var.")


def _truth_on(canvas: np.ndarray, box: Box, line: int, label: str = "GT") -> None:
    """A ground-truth box, white, labelled (`GT`, `GT A`) under it, in place."""
    x, y, w, h = box
    cv2.rectangle(canvas, (round(x), round(y)), (round(x + w), round(y + h)), TRUTH, line)
    origin = (round(x), round(y + h) + 14 * line)
    cv2.putText(canvas, label, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.45 * line, TRUTH, line)


def _legend_on(canvas: np.ndarray, limits: Limits, name: str) -> None:
    """The overlay's colour scale (`name`: what it maps) in the frame's top-right corner, in
    place (drawn at 220 px and enlarged with wide frames, so it reads at the same size on the
    page)."""
    width = min(220, canvas.shape[1])
    bar = legend_bar(width, limits)
    _label(bar, f"{name} p2-p98", (width // 2 - 55, 22), (80, 80, 80))
    zoom = max(1, round(canvas.shape[1] / 640))
    bar = cv2.resize(bar, (width * zoom, bar.shape[0] * zoom), interpolation=cv2.INTER_NEAREST)
    bar = bar[:, : canvas.shape[1]]
    canvas[: bar.shape[0], canvas.shape[1] - bar.shape[1] :] = bar


def scaled_for_display(image: np.ndarray, max_width: int) -> np.ndarray:
    """`image` scaled down (area interpolation) so its width is at most `max_width`."""
    height, width = image.shape[:2]
    if width <= max_width:
        return image
    scale = max_width / width
    return cv2.resize(
        image, (max_width, max(1, round(height * scale))), interpolation=cv2.INTER_AREA
    )


def thumbnail(image: np.ndarray, width: int = 160) -> np.ndarray:
    """A small RGB copy of a frame for the camera frustum."""
    return scaled_for_display(as_rgb(image), width)
