"""A long sequence rendered on demand: a seeded texture, tiled, drifting under the camera.

For soak tests and memory benchmarks: thousands of frames with no file and no memory per frame
(each frame is cut from the tiled texture when it is read), several well-textured targets that
stay in view (the whole picture moves along a smooth closed path, so every box moves with it),
and exact boxes for every frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from autotrack.errors import InputError
from autotrack.io.frames import FrameSource
from autotrack.synthetic.textures import smooth_noise

Box = tuple[float, float, float, float]


@dataclass(frozen=True)
class DriftSettings:
    """How a drifting-texture sequence looks and moves."""

    frames: int = 3000
    """Number of frames."""
    width: int = 160
    """Frame width (pixels)."""
    height: int = 120
    """Frame height (pixels)."""
    amplitude_px: float = 12.0
    """Largest shift of the picture from its rest position along each axis (pixels)."""
    period_frames: int = 240
    """Frames per round of the closed path the picture drifts along."""
    target_side: int = 24
    """Side of each target's square box (pixels)."""
    seed: int = 0
    """Seed of the texture."""

    def check(self) -> None:
        """InputError when the settings cannot make a sequence."""
        if self.frames < 2:
            raise InputError("a drifting sequence needs at least 2 frames")
        if min(self.width, self.height) < 4 * self.target_side:
            raise InputError("the frame must be at least four target sides wide and high")
        if not (0 <= self.amplitude_px < self.target_side and self.period_frames >= 2):
            raise InputError("amplitude must be below the target side, the period at least 2")


class DriftingTexture(FrameSource):
    """The frames of a `DriftSettings` sequence, each rendered when read (RGB uint8)."""

    def __init__(self, settings: DriftSettings | None = None, name: str = "drift") -> None:
        settings = settings or DriftSettings()
        settings.check()
        self.settings = settings
        self.name = name
        self.fps = 30.0
        rng = np.random.default_rng(settings.seed)
        side = 2 * max(settings.width, settings.height)
        grey = smooth_noise(rng, side, side, cell_texels=6.0)
        tint = smooth_noise(rng, side, side, cell_texels=24.0)
        channels = [grey, 0.6 * grey + 0.4 * tint, tint]
        texture = np.stack([np.clip(128 + 90 * c, 0, 255) for c in channels], axis=2)
        self._texture = texture.astype(np.uint8)

    def __len__(self) -> int:
        return self.settings.frames

    def offset(self, index: int) -> tuple[float, float]:
        """(dx, dy): where the picture sits on frame `index` relative to frame 0 (pixels)."""
        s = self.settings
        phase = 2.0 * math.pi * index / s.period_frames
        return (s.amplitude_px * math.sin(phase), s.amplitude_px * math.sin(2.0 * phase) / 2.0)

    def boxes(self, count: int, index: int = 0) -> list[Box]:
        """`count` target boxes (x, y, w, h, 0-based) on frame `index`, spread over the frame."""
        s = self.settings
        dx, dy = self.offset(index)
        columns = max(1, math.ceil(math.sqrt(count)))
        rows = math.ceil(count / columns)
        out: list[Box] = []
        for k in range(count):
            cx = s.width * (k % columns + 1) / (columns + 1)
            cy = s.height * (k // columns + 1) / (rows + 1)
            side = float(s.target_side)
            out.append((cx - side / 2 + dx, cy - side / 2 + dy, side, side))
        return out

    def _read_bgr(self, index: int) -> np.ndarray:
        s = self.settings
        dx, dy = self.offset(index)
        # Frame pixel (u, v) shows texture pixel (u + ox - dx, v + oy - dy): the texture's
        # centre sits at the frame's centre, shifted by (dx, dy).
        ox = (self._texture.shape[1] - s.width) / 2
        oy = (self._texture.shape[0] - s.height) / 2
        inverse = np.array([[1.0, 0.0, ox - dx], [0.0, 1.0, oy - dy]])
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        size = (s.width, s.height)
        return cv2.warpAffine(self._texture, inverse, size, flags=flags, borderMode=cv2.BORDER_WRAP)

    def close(self) -> None:
        """Nothing to release."""
