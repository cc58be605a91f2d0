"""A pipeline's targets and what it reports per frame."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from autotrack.result import PoseEstimate, TrackResult

Box = tuple[float, float, float, float]

SIGNAL_NAMES = ("peak_score", "global_variation", "theta_ref", "theta", "aberrant")
"""Per-target, per-frame numbers kept as arrays over the sequence (for plots)."""


@dataclass
class TrackedTarget:
    """One tracked object as the caller defined it, with its results so far."""

    id: str
    """'T1', 'T2', ... in the order the targets were added; never reused within a run."""
    number: int
    """1, 2, ...: the number in the id."""
    landmark_id: str | None
    """Scene landmark this target localises (None: tracked only)."""
    results: dict[int, TrackResult] = field(default_factory=dict)
    """Results by 0-based frame index (the box's frame holds the init result)."""
    signals: dict[str, np.ndarray] = field(default_factory=dict)
    """Name in SIGNAL_NAMES -> float64 array over all frames, NaN where nothing is known."""

    @property
    def last_frame(self) -> int:
        """Last frame with a result (-1 before the box is drawn)."""
        return max(self.results, default=-1)

    def grow(self, frame_count: int) -> None:
        """Extend the signal arrays to `frame_count` frames (NaN for the new ones)."""
        for name, values in self.signals.items():
            self.signals[name] = grown(values, frame_count)


@dataclass(frozen=True)
class FrameOutcome:
    """What the pipeline knows about one frame."""

    frame_index: int
    tracks: dict[str, TrackResult]
    """Target id -> result on this frame (targets without one are absent)."""
    landmark_ids: dict[str, str | None]
    """Target id -> the landmark it localises (None: tracked only)."""
    pose: PoseEstimate | None
    """Camera pose (None without a scene or landmark targets)."""

    @property
    def landmark_tracks(self) -> dict[str, TrackResult]:
        """Landmark id -> result, for the targets that localise a landmark."""
        return {
            landmark: self.tracks[target_id]
            for target_id, landmark in self.landmark_ids.items()
            if landmark is not None and target_id in self.tracks
        }

    @property
    def image_points(self) -> dict[str, tuple[float, float]]:
        """Landmark id -> box centre (the point given to the pose solver)."""
        return {landmark: result.center for landmark, result in self.landmark_tracks.items()}


def number_of(target_id: str, fallback: int) -> int:
    """The number in a pipeline's target id "T<number>" (`fallback` for other ids)."""
    digits = target_id[1:]
    return int(digits) if target_id.startswith("T") and digits.isdigit() else fallback


def grown(values: np.ndarray, count: int) -> np.ndarray:
    """`values` extended with NaN to `count` entries."""
    return np.append(values, np.full(count - len(values), np.nan))
