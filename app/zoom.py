"""Zoom and pan on the frame canvas: the part of the frame the canvas shows, and how a drag on
the zoomed canvas maps back to frame pixels.

The canvas shows a window of the frame (the whole frame at zoom 1). The window is cut out of the
drawn frame, letterboxed to the canvas like a whole frame (app/canvas.py) and sent at its own
resolution, so a 1280x720 frame at zoom 4 sends its 320x180 window's pixels and the browser
enlarges them: a 25 px target then spans ~100 screen pixels. A drag maps through the window's
letterbox to window pixels, then by the window's offset to frame pixels: one scale, two
offsets, the same exactness as at zoom 1. No viser here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from autotrack_studio.boxes import Box
from autotrack_studio.canvas import Letterbox, fit_letterbox

MAX_ZOOM = 8.0


@dataclass(frozen=True)
class ZoomWindow:
    """The frame pixels the canvas shows: columns x .. x + width, rows y .. y + height."""

    x: int
    y: int
    width: int
    height: int

    def crop(self, image: np.ndarray) -> np.ndarray:
        """The window's part of a frame-sized image (a view, not a copy)."""
        return image[self.y : self.y + self.height, self.x : self.x + self.width]


def zoom_window(
    frame_size: tuple[int, int], zoom: float, centre: tuple[float, float] | None = None
) -> ZoomWindow:
    """The window of a (w, h) frame shown at `zoom` (1 = the whole frame, at most MAX_ZOOM),
    centred on `centre` (frame pixels; None: the frame's centre) and moved inside the frame."""
    width, height = frame_size
    zoom = min(max(float(zoom), 1.0), MAX_ZOOM)
    shown_width = max(2, min(width, round(width / zoom)))
    shown_height = max(2, min(height, round(height / zoom)))
    cx, cy = centre if centre is not None else (width / 2.0, height / 2.0)
    x = min(max(round(cx - shown_width / 2.0), 0), width - shown_width)
    y = min(max(round(cy - shown_height / 2.0), 0), height - shown_height)
    return ZoomWindow(x, y, shown_width, shown_height)


@dataclass(frozen=True)
class CanvasMapping:
    """How canvas fractions map to frame pixels: through the window's letterbox, then its
    offset."""

    window: ZoomWindow
    letterbox: Letterbox
    """The window letterboxed to the canvas (its 'frame' is the window)."""

    def screen_to_frame(self, u: float, v: float) -> tuple[float, float]:
        """Canvas fractions (0..1, top-left origin) to frame pixel coordinates."""
        x, y = self.letterbox.screen_to_frame(u, v)
        return (x + self.window.x, y + self.window.y)

    def frame_to_screen(self, x: float, y: float) -> tuple[float, float]:
        """Frame pixel coordinates to canvas fractions."""
        return self.letterbox.frame_to_screen(x - self.window.x, y - self.window.y)

    def rect_inside(self, screen_min: tuple[float, float], screen_max: tuple[float, float]) -> bool:
        """Whether a rect-select (canvas fractions) lies within the window shown."""
        return self.letterbox.rect_inside(screen_min, screen_max)

    def rect_to_box(
        self, screen_min: tuple[float, float], screen_max: tuple[float, float]
    ) -> Box | None:
        """A rect-select as a frame box, cut at the window's edges (None: it misses the
        window or is thinner than 2 window pixels)."""
        box = self.letterbox.rect_to_box(screen_min, screen_max)
        if box is None:
            return None
        return (box[0] + self.window.x, box[1] + self.window.y, box[2], box[3])


def canvas_mapping(
    frame_size: tuple[int, int], canvas_size: tuple[int, int], window: ZoomWindow | None = None
) -> CanvasMapping:
    """The mapping of a canvas of `canvas_size` showing `window` of a `frame_size` frame (None:
    the whole frame)."""
    window = window or ZoomWindow(0, 0, *frame_size)
    return CanvasMapping(window, fit_letterbox((window.width, window.height), canvas_size))
