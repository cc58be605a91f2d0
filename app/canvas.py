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
    (255, 64, 64),
    (64, 200, 255),
    (255, 200, 0),
    (120, 255, 80),
    (255, 80, 255),
    (255, 140, 0),
    (0, 255, 200),
    (180, 120, 255),
)
"""RGB colour of target number i (cycled)."""


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
    """The RGB frame padded with black to the letterbox, scaled down to at most `max_width`."""
    padded = np.zeros((letterbox.padded_height, letterbox.padded_width, 3), dtype=np.uint8)
    rgb = as_rgb(image)
    padded[
        letterbox.offset_y : letterbox.offset_y + letterbox.frame_height,
        letterbox.offset_x : letterbox.offset_x + letterbox.frame_width,
    ] = rgb
    if letterbox.padded_width > max_width:
        scale = max_width / letterbox.padded_width
        size = (max_width, max(1, round(letterbox.padded_height * scale)))
        padded = cv2.resize(padded, size, interpolation=cv2.INTER_AREA)
    return padded


def as_rgb(image: np.ndarray) -> np.ndarray:
    """An HxWx3 uint8 view or copy of a grey or RGB frame."""
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    return image


def normalised(values: np.ndarray) -> np.ndarray:
    """A float map min-max scaled to 0..1 (all zeros when flat; NaN and inf count as 0)."""
    finite = np.nan_to_num(values.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    low, high = float(finite.min()), float(finite.max())
    if high <= low:
        return np.zeros(finite.shape, np.float32)
    return (finite - low) / (high - low)


def colour_map(values: np.ndarray) -> np.ndarray:
    """A float map as an RGB image (min-max scaled, OpenCV's JET colour map)."""
    scaled = np.round(normalised(values) * 255.0).astype(np.uint8)
    return cv2.cvtColor(cv2.applyColorMap(scaled, cv2.COLORMAP_JET), cv2.COLOR_BGR2RGB)


def map_panel(values: np.ndarray | None, size: int = 160) -> np.ndarray:
    """A colour-mapped map enlarged to `size` pixels square for a GUI image (grey if None)."""
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


def blend_map(image: np.ndarray, values: np.ndarray, region: Box, opacity: float) -> None:
    """Blend a colour-mapped map over `region` (x, y, w, h) of `image`, in place.

    Each pixel's opacity grows with the map's value, so the high responses stand out and the
    low ones leave the frame visible.
    """
    x, y, w, h = region
    left, top = round(x), round(y)
    width, height = max(1, round(w)), max(1, round(h))
    size = (width, height)
    coloured = cv2.resize(colour_map(values), size, interpolation=cv2.INTER_LINEAR)
    weight = cv2.resize(normalised(values), size, interpolation=cv2.INTER_LINEAR) * opacity
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


def draw_overlays(
    frame: np.ndarray,
    targets: Sequence[TargetDrawing],
    map_kind: str,
    max_width: int | None = None,
    map_opacity: float = 0.7,
) -> np.ndarray:
    """The frame, scaled down to at most `max_width` pixels, with each target's box, label and
    response peak drawn, and its response map ('response') or local variation map
    ('local_variation') blended over its search region. An aberrant frame gets a red outer box
    and the word ABERRANT. The input frame is not modified."""
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
    if map_kind in ("response", "local_variation"):
        for target in targets:
            result = target.result
            if result is None:
                continue
            values = result.response_map if map_kind == "response" else result.local_variation
            if values is not None:
                blend_map(canvas, values, scaled(result.search_box), map_opacity)
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
                (255, 0, 0),
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
