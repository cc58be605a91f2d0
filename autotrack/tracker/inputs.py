"""What enters the tracker from a caller: the first box and the frames, checked."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from autotrack.errors import BoxError, InputError


def validate_box(
    box: Sequence[float], image_size_wh: tuple[int, int], name: str | None = None
) -> tuple[float, ...]:
    """Check an initial (x, y, w, h) box: finite, positive size, centre inside the image.

    `name` is how the messages call the box (default: "box" and its values), for a caller whose
    user typed it in another convention (the CLI's 1-based `--init`).
    """
    try:
        values = tuple(float(v) for v in box)
    except (TypeError, ValueError) as error:
        raise BoxError(f"box must be four numbers x, y, w, h; got {box!r}") from error
    shown = name or f"box {values}"
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise BoxError(f"{shown} must be four finite numbers x, y, w, h")
    x, y, w, h = values
    if w < 1 or h < 1:
        raise BoxError(f"{shown} has zero size: width and height must be at least 1 pixel")
    width, height = image_size_wh
    cx, cy = x + w / 2.0, y + h / 2.0
    if not (0 <= cx < width and 0 <= cy < height):
        raise BoxError(
            f"{shown} lies outside the {width}x{height} image (its centre must be inside)"
        )
    return values


def as_image(frame: np.ndarray) -> np.ndarray:
    if not isinstance(frame, np.ndarray) or frame.ndim not in (2, 3) or frame.size == 0:
        raise InputError("a frame must be a non-empty HxW or HxWx3 numpy array")
    if frame.ndim == 3 and frame.shape[2] == 4:
        frame = frame[:, :, :3]
    if frame.ndim == 3 and frame.shape[2] not in (1, 3):
        raise InputError(f"a frame must have 1 or 3 channels, not {frame.shape[2]}")
    if frame.dtype != np.uint8:
        frame = np.clip(frame, 0, 255).astype(np.uint8)
    if frame.ndim == 3 and frame.shape[2] == 1:
        frame = frame[:, :, 0]
    return frame
