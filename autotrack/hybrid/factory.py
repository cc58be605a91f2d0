"""Where a tracker's name becomes a tracker: the AutoTrack presets, `nanotrack` and `hybrid`.

Every tracker made here has AutoTrack's call shape (`init(frame_rgb, box)` and
`update(frame_rgb)` returning `TrackResult`s); code that chooses a tracker by name calls
`make_tracker` instead of building `AutoTrack` itself.
"""

from __future__ import annotations

from pathlib import Path

from autotrack.errors import InputError
from autotrack.params import PRESETS, TrackerParams, preset

NANOTRACK, HYBRID = "nanotrack", "hybrid"
SIAMESE_TRACKERS: tuple[str, ...] = (NANOTRACK, HYBRID)
"""The trackers beside the AutoTrack presets: NanoTrack and the hybrid."""
TRACKERS: tuple[str, ...] = (*PRESETS, *SIAMESE_TRACKERS)
"""Every name `make_tracker` accepts: the AutoTrack presets, NanoTrack, the hybrid."""


class BoxesOf:
    """A tracker returning `TrackResult`s seen as a benchmark's box tracker (boxes only)."""

    def __init__(self, tracker) -> None:
        self.tracker = tracker

    def init(self, frame_rgb, box) -> tuple[float, float, float, float]:
        """Start on the first frame; returns the box."""
        return tuple(self.tracker.init(frame_rgb, box).box)

    def update(self, frame_rgb) -> tuple[float, float, float, float]:
        """Track into the next frame; returns the box."""
        return tuple(self.tracker.update(frame_rgb).box)


def make_tracker(
    name: str,
    params: TrackerParams | None = None,
    colour_table: str | Path | None = None,
):
    """A fresh tracker by name (see TRACKERS). `params` replaces a preset's parameters (for the
    hybrid: its correlation filter's, `autotrack+` by default); `colour_table` applies to the
    AutoTrack presets and the hybrid's filter."""
    key = name.strip().lower()
    if key == NANOTRACK:
        from autotrack.nanotrack import NanoTrack

        return NanoTrack()
    if key == HYBRID:
        from autotrack.hybrid.tracker import HybridParams, HybridTracker

        return HybridTracker(HybridParams(params or preset("autotrack+", colour_table)))
    if key not in PRESETS:
        raise InputError(f"unknown tracker {name!r}; choose from {', '.join(TRACKERS)}")
    from autotrack import AutoTrack

    return AutoTrack(params or preset(key, colour_table))
