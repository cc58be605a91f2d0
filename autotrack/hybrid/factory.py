"""Where a tracker's name becomes a tracker: the AutoTrack presets, `nanotrack` and `hybrid`.

Every tracker made here has AutoTrack's call shape (`init(frame_rgb, box)` and
`update(frame_rgb)` returning `TrackResult`s); code that chooses a tracker by name calls
`make_tracker` instead of building `AutoTrack` itself.
"""

from __future__ import annotations

from pathlib import Path

from autotrack.errors import InputError
from autotrack.params import PRESETS, TrackerParams, preset
from autotrack.result import TrackResult

NANOTRACK, HYBRID = "nanotrack", "hybrid"
SIAMESE_TRACKERS: tuple[str, ...] = (NANOTRACK, HYBRID)
"""The trackers beside the AutoTrack presets: NanoTrack and the hybrid."""
TRACKERS: tuple[str, ...] = (*PRESETS, *SIAMESE_TRACKERS)
"""Every name `make_tracker` accepts: the AutoTrack presets, NanoTrack, the hybrid."""
TRUSTED: tuple[str, ...] = ("both", "filter", "siamese")
"""What a hybrid result's `trusted` says (`autotrack.hybrid.tracker`: BOTH, FILTER, SIAMESE),
in the order of their codes (`trusted_code`)."""


def tracker_key(name: str) -> str:
    """`name` as `make_tracker` knows it (trimmed, lower case); InputError for an unknown one."""
    key = name.strip().lower()
    if key not in TRACKERS:
        raise InputError(f"unknown tracker {name!r}; choose from {', '.join(TRACKERS)}")
    return key


def tracker_params(name: str, colour_table: str | Path | None = None) -> TrackerParams:
    """The TrackerParams a run with tracker `name` tracks, records and resumes with: a preset's
    own; the hybrid's correlation filter's (`autotrack+`); NanoTrack has none of its own and
    records the faithful preset's, which it does not use."""
    key = tracker_key(name)
    if key == HYBRID:
        return preset("autotrack+", colour_table)
    return preset("autotrack" if key == NANOTRACK else key, colour_table)


def tracker_name(tracker: str | None, params: TrackerParams) -> str:
    """The name of the tracker a run makes from `tracker` (a name, None: AutoTrack) and
    `params`: `nanotrack` or `hybrid`, else the AutoTrack variant `params` describe."""
    key = None if tracker is None else tracker_key(tracker)
    return key if key in SIAMESE_TRACKERS else params.name


def trusted_of(result: object) -> str | None:
    """Which tracker a hybrid result's box came from (one of TRUSTED); None for any other
    tracker's result."""
    trusted = getattr(result, "trusted", None)
    return trusted if trusted in TRUSTED else None


def trusted_code(result: object) -> float:
    """A hybrid result's `trusted` as its index in TRUSTED; NaN for any other result."""
    trusted = trusted_of(result)
    return float("nan") if trusted is None else float(TRUSTED.index(trusted))


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
    key = tracker_key(name)
    if key == NANOTRACK:
        from autotrack.nanotrack import NanoTrack

        return NanoTrack()
    if key == HYBRID:
        from autotrack.hybrid.tracker import HybridParams, HybridTracker

        return HybridTracker(HybridParams(params or preset("autotrack+", colour_table)))
    from autotrack import AutoTrack

    return AutoTrack(params or preset(key, colour_table))


def with_trusted(result: TrackResult, trusted: str) -> TrackResult:
    """`result` as a hybrid's result that trusted `trusted` (one of TRUSTED), without the two
    trackers' own results (a result rebuilt from a recording or a history's columns)."""
    from autotrack.hybrid.tracker import HybridResult

    fields = {name: getattr(result, name) for name in TrackResult.__dataclass_fields__}
    return HybridResult(**fields, trusted=trusted)
