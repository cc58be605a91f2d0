"""Compiling the tracker's kernels before the first box: a few frames of a synthetic target."""

from __future__ import annotations

import time

import cv2
import numpy as np

from autotrack.params import TrackerParams
from autotrack.tracker.tracker import AutoTrack


def warm_up(params: TrackerParams | None = None) -> float:
    """Compile (or load from numba's cache) every kernel the tracker runs, by tracking a small
    synthetic target for four frames in colour and in grey; returns the seconds it took.

    The first box a user draws then answers at once instead of waiting for the compiler.
    """
    started = time.perf_counter()
    params = params or TrackerParams()
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 64, (120, 160, 3), dtype=np.uint8)
    frame[40:70, 60:90] = (230, 180, 40)
    for image in (frame, cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)):
        tracker = AutoTrack(params)
        tracker.init(image, (60.0, 40.0, 30.0, 30.0))
        for shift in (1, 2, 3):
            tracker.update(np.roll(image, shift, axis=1))
    return time.perf_counter() - started
