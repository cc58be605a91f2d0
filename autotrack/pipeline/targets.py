"""A pipeline's targets and what it reports per frame."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace

import numpy as np

from autotrack.errors import BoxError, InputError
from autotrack.localization.scene import Scene
from autotrack.pipeline.history import ResultHistory
from autotrack.pipeline.posing import SolverInput
from autotrack.result import PoseEstimate, TrackResult
from autotrack.tracker.inputs import validate_box

Box = tuple[float, float, float, float]

SIGNAL_NAMES = ("peak_score", "global_variation", "theta_ref", "theta", "aberrant", "trusted")
"""Per-target, per-frame numbers kept as arrays over the sequence (for plots); `trusted` is
the hybrid's `autotrack.hybrid.factory.trusted_code` (NaN for other trackers)."""


def checked_box(frame: np.ndarray, box: Box, owner: str | None = None) -> Box:
    """The box as four floats, checked against its frame as the tracker will; a refusal names
    `owner` (the landmark or target the box is for), when given."""
    height, width = frame.shape[:2]
    try:
        x, y, w, h = validate_box(box, (width, height))
    except BoxError as error:
        if owner is None:
            raise
        raise BoxError(f"{owner}: {error}") from None
    return (x, y, w, h)


def free_numbers(taken: set[int], count: int) -> list[int]:
    """The `count` smallest positive numbers not in `taken` (a deleted target's number is
    given again, so ids stay T1..Tn)."""
    numbers: list[int] = []
    candidate = 1
    while len(numbers) < count:
        if candidate not in taken:
            numbers.append(candidate)
        candidate += 1
    return numbers


@dataclass
class TrackedTarget:
    """One tracked object as the caller defined it, with its results so far."""

    id: str
    """'T1', 'T2', ...: the smallest number no live target has when it was added."""
    number: int
    """1, 2, ...: the number in the id."""
    landmark_id: str | None
    """Scene landmark this target localises (None: tracked only)."""
    results: ResultHistory = field(default_factory=ResultHistory)
    """Results by 0-based frame index (the box's frame holds the init result), as columns; the
    recent map window's results kept whole."""
    frame_count: int = 0
    """Frames of the sequence so far (the length of the `signals` arrays)."""

    @classmethod
    def new(
        cls, target_id: str, number: int, landmark_id: str | None, frames: int
    ) -> TrackedTarget:
        """A target with no results yet, on a sequence of `frames` frames."""
        return cls(id=target_id, number=number, landmark_id=landmark_id, frame_count=frames)

    @property
    def last_frame(self) -> int:
        """Last frame with a result (-1 before the box is drawn)."""
        return self.results.last_frame

    @property
    def maps_from(self) -> int:
        """The results before this frame have had their maps dropped (`keep`); the recording
        has them."""
        return self.results.maps_from

    @property
    def signals(self) -> dict[str, np.ndarray]:
        """Name in SIGNAL_NAMES -> a new float64 array over all frames, NaN where the target
        has no result (for plots; made from the results' columns)."""
        results = self.results
        arrays = {}
        for name in SIGNAL_NAMES:
            values = np.full(self.frame_count, np.nan)
            if name in ("aberrant", "trusted"):
                column = getattr(results, name)
            else:
                column = results.column(name)
            values[results.frames] = column
            arrays[name] = values
        return arrays

    def keep(self, result: TrackResult, map_window: int) -> None:
        """`result` as the target's result on its frame; the maps of the results `map_window`
        or more frames before it are dropped (0: its own too)."""
        self.results.put(result, map_window)

    def truncate_after(self, frame_index: int) -> list[int]:
        """Drop the results after `frame_index`; the frames dropped, in order."""
        return self.results.truncate_after(frame_index)

    def grow(self, frame_count: int) -> None:
        """The sequence now has `frame_count` frames (a live source grows)."""
        self.frame_count = frame_count


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
    solver: SolverInput | None = None
    """What the pose solver was given (None: no pose solved on this frame)."""

    def without_maps(self) -> FrameOutcome:
        """This outcome with the results' maps dropped (what a caller keeping every frame's
        outcome needs: boxes, signals and pose, not a few kB of maps per target and frame)."""
        return replace(self, tracks={k: r.without_maps() for k, r in self.tracks.items()})

    @property
    def landmark_tracks(self) -> dict[str, TrackResult]:
        """Landmark id -> result, for the targets that localise a landmark."""
        return {
            landmark: self.tracks[target_id]
            for target_id, landmark in self.landmark_ids.items()
            if landmark is not None and target_id in self.tracks
        }

    @property
    def box_centres(self) -> dict[str, tuple[float, float]]:
        """Landmark id -> the tracker's box centre."""
        return {landmark: result.center for landmark, result in self.landmark_tracks.items()}

    @property
    def image_points(self) -> dict[str, tuple[float, float]]:
        """Landmark id -> the point given to the pose solver: the box centre, or the refined
        point when refinement is on and accepted (NaN when the out-of-view gate left it out)."""
        return self.box_centres if self.solver is None else dict(self.solver.points)

    @property
    def refined(self) -> dict[str, bool]:
        """Landmark id -> whether the refined point replaced the box centre on this frame."""
        return {} if self.solver is None else dict(self.solver.refined)

    @property
    def events(self) -> dict[str, str]:
        """Landmark id -> what happened to it beyond tracking ("out of view", "re-acquired at
        (u, v), match m")."""
        return {} if self.solver is None else dict(self.solver.events)


def check_landmark(
    scene: Scene | None,
    targets: Iterable[TrackedTarget],
    landmark_id: str | None,
    target_id: str | None,
) -> None:
    """InputError unless `landmark_id` (None: no landmark) is a landmark of `scene` that no
    target but `target_id` tracks."""
    if landmark_id is None:
        return
    if scene is None:
        raise InputError("no scene is loaded, so boxes cannot be tied to landmarks")
    if landmark_id not in scene.landmark_ids:
        known = ", ".join(scene.landmark_ids)
        raise InputError(f"unknown landmark {landmark_id!r}; the scene has {known}")
    for other in targets:
        if other.id != target_id and other.landmark_id == landmark_id:
            raise InputError(f"landmark {landmark_id} is already tracked by {other.id}")


def number_of(target_id: str, fallback: int) -> int:
    """The number in a pipeline's target id "T<number>" (`fallback` for other ids)."""
    digits = target_id[1:]
    return int(digits) if target_id.startswith("T") and digits.isdigit() else fallback


def grown(values: np.ndarray, count: int) -> np.ndarray:
    """`values` extended with NaN to `count` entries."""
    return np.append(values, np.full(count - len(values), np.nan))
