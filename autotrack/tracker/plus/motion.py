"""A constant-velocity motion prior over the next displacement (`TrackerParams.motion_prior`).

Used only to weigh distinct response peaks against each other (memory.disambiguate), never to
move the search region: of two look-alikes the one on the target's path wins unless the other
has clearly more appearance evidence. The model is a constant-velocity Kalman filter's
prediction with its noise measured rather than set: the predicted motion is the running mean of
the last confident motions and its spread the running root mean square of their deviations
from it, so a smoothly moving target gets a sharp prior and an erratic one (a shaking camera,
repeated frames) a broad one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MotionPrior:
    """A Gaussian prior over a peak's displacement (cells) around `predicted`."""

    predicted: tuple[float, float]
    """Displacement (row, col, cells) expected from the recent motion."""
    sigma: float
    """Standard deviation (cells) of the deviation from the predicted displacement."""

    def likelihood(self, row: float, col: float) -> float:
        """exp(-d^2 / (2 sigma^2)), d the distance of (row, col) from the prediction."""
        distance2 = (row - self.predicted[0]) ** 2 + (col - self.predicted[1]) ** 2
        return math.exp(-distance2 / (2.0 * self.sigma**2))


class MotionModel:
    """Running mean and spread of the target's confident per-frame motions (pixels).

    `rate` is the averaging rate per observed motion; the prior is given only once 1 / rate
    motions were seen (the averages are a guess before) and only when the last frame's motion
    was observed (not after a jump or a frame below the confidence gate).
    """

    def __init__(self, rate: float) -> None:
        self.rate = rate
        self.mean = np.zeros(2)
        self.variance = 0.0
        self.observed = 0
        self.last_known = False

    def observe(self, motion: np.ndarray | None) -> None:
        """Fold one frame's motion (row, col, pixels) in, or None when it is not known."""
        self.last_known = motion is not None
        if motion is None:
            return
        self.observed += 1
        rate = max(self.rate, 1.0 / self.observed)  # a plain mean over the first motions
        deviation = np.asarray(motion, dtype=np.float64) - self.mean
        self.mean = self.mean + rate * deviation
        self.variance += rate * (float(deviation @ deviation) - self.variance)

    def prior(self, floor_sigma: float, cell_pixels: float) -> MotionPrior | None:
        """The prior in cells: sigma^2 = floor^2 + the motion's spread^2 (floor in pixels)."""
        if not self.last_known or self.observed * self.rate < 1.0:
            return None
        sigma = math.sqrt(floor_sigma**2 + self.variance) / cell_pixels
        row, col = self.mean / cell_pixels
        return MotionPrior((float(row), float(col)), sigma)
