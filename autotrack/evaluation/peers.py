"""Every tracker a benchmark compares, behind one interface: `init(frame, box)` / `update(frame)`.

Frames are RGB (or grey) uint8 arrays and boxes 0-based (x, y, w, h) floats, as for AutoTrack.
The AutoTrack presets (the paper's ablation) run our tracker; `csrt`, `kcf` and `mosse` run
OpenCV's trackers (CSRT is the CSR-DCF of the paper's comparison). The OpenCV adapter converts
frames to BGR (grey frames to three channels) and rounds boxes to integers, as OpenCV wants.
When an OpenCV tracker reports failure for a frame it returns no box; the adapter then keeps
its last box, which is how the benchmark toolkits score a tracker that stops reporting.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from autotrack.errors import InputError
from autotrack.hybrid import factory
from autotrack.params import PRESETS, TrackerParams, preset

Box = tuple[float, float, float, float]

OPENCV_TRACKERS: dict[str, Callable[[], cv2.Tracker]] = {
    "csrt": cv2.TrackerCSRT_create,
    "kcf": cv2.TrackerKCF_create,
    "mosse": cv2.legacy.TrackerMOSSE_create,
}
"""OpenCV peers by name."""

TRACKER_NAMES: tuple[str, ...] = (*factory.TRACKERS, *OPENCV_TRACKERS)
"""Every name `make_tracker` accepts: the AutoTrack presets, NanoTrack and the hybrid, then the
OpenCV peers."""


class BoxTracker(Protocol):
    """What the benchmark runner needs from a tracker."""

    def init(self, frame_rgb: np.ndarray, box: Sequence[float]) -> Box:
        """Start on the first frame from a 0-based (x, y, w, h) box; returns the box."""
        ...

    def update(self, frame_rgb: np.ndarray) -> Box:
        """Track into the next frame; returns the 0-based (x, y, w, h) box."""
        ...


class AutoTrackPeer:
    """AutoTrack with any parameters (a preset, a sweep's combination) returning boxes only."""

    def __init__(self, params: TrackerParams) -> None:
        from autotrack.tracker.tracker import AutoTrack

        self.params = params
        self._tracker = AutoTrack(params)

    def init(self, frame_rgb: np.ndarray, box: Sequence[float]) -> Box:
        return tuple(self._tracker.init(frame_rgb, box).box)

    def update(self, frame_rgb: np.ndarray) -> Box:
        return tuple(self._tracker.update(frame_rgb).box)


def _opencv_rect(box: Sequence[float]) -> tuple[int, int, int, int]:
    x, y, w, h = (float(v) for v in box)
    return (round(x), round(y), max(1, round(w)), max(1, round(h)))


def _to_bgr(frame_rgb: np.ndarray) -> np.ndarray:
    if frame_rgb.ndim == 2:
        return cv2.cvtColor(frame_rgb, cv2.COLOR_GRAY2BGR)
    return cv2.cvtColor(frame_rgb, cv2.COLOR_RGB2BGR)


class OpenCVPeer:
    """An OpenCV tracker (CSRT, KCF, MOSSE) that keeps its last box when it reports failure."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._tracker = OPENCV_TRACKERS[name]()
        self._last_box: Box | None = None

    def init(self, frame_rgb: np.ndarray, box: Sequence[float]) -> Box:
        rect = _opencv_rect(box)
        self._tracker.init(_to_bgr(frame_rgb), rect)
        self._last_box = tuple(float(v) for v in rect)
        return self._last_box

    def update(self, frame_rgb: np.ndarray) -> Box:
        if self._last_box is None:
            raise InputError(f"{self.name}: update() called before init()")
        ok, rect = self._tracker.update(_to_bgr(frame_rgb))
        if ok:
            self._last_box = tuple(float(v) for v in rect)
        return self._last_box


def make_tracker(name: str, colour_table: str | Path | None = None) -> BoxTracker:
    """A fresh tracker by name (see TRACKER_NAMES). `colour_table` (the published Color Names
    table) applies to the AutoTrack presets only."""
    key = name.strip().lower()
    if key in PRESETS:
        return AutoTrackPeer(preset(key, colour_table))
    if key in OPENCV_TRACKERS:
        return OpenCVPeer(key)
    if key in factory.SIAMESE_TRACKERS:
        return factory.BoxesOf(factory.make_tracker(key, colour_table=colour_table))
    raise InputError(f"unknown tracker {name!r}; choose from {', '.join(TRACKER_NAMES)}")


def colour_feature_of(name: str, colour_table: str | Path | None = None) -> str | None:
    """The colour feature a named tracker uses: 'lab11', 'table:<path>', or None (OpenCV)."""
    key = name.strip().lower()
    if key not in PRESETS:
        return None
    params = preset(key, colour_table)
    if params.colour_feature == "table":
        return f"table:{params.colour_table_path}"
    return params.colour_feature
