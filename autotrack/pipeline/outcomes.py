"""Every frame's outcome of a localisation run, kept compactly for its report (`OutcomeLog`).

`autotrack localize` reports on the whole run once it ends (TUM poses, the per-frame tracks
CSV, Table 3). Keeping each frame's `FrameOutcome` would keep its results as Python objects
(~3 kB per frame with four landmarks); the log keeps the landmarks' boxes, peak scores and
aberrance flags as columns, and the poses and solver inputs the pipeline made (objects it
holds anyway).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from autotrack.pipeline.history import doubled
from autotrack.pipeline.posing import SolverInput
from autotrack.pipeline.targets import FrameOutcome
from autotrack.result import PoseEstimate

Box = tuple[float, float, float, float]
_PEAK, _ABERRANT = 4, 5
"""Columns of a landmark's row after its box (x, y, w, h)."""


class OutcomeLog:
    """A run's outcomes, frame after frame (`append`), for the landmarks in `landmark_ids`."""

    def __init__(self, landmark_ids: Sequence[str], capacity: int = 256) -> None:
        self.landmark_ids = tuple(landmark_ids)
        self._column = {landmark: k for k, landmark in enumerate(self.landmark_ids)}
        self._frames = np.zeros(capacity, dtype=np.int64)
        self._tracks = np.zeros((capacity, len(self.landmark_ids), 6))
        self._count = 0
        self.poses: list[PoseEstimate | None] = []
        """Each frame's pose (None: none estimated), as the pipeline made it."""
        self.solver_inputs: list[SolverInput | None] = []
        """What the pose solver was given on each frame (None: no pose solved there)."""

    def append(self, outcome: FrameOutcome) -> None:
        """Keep what the report needs of `outcome` (its maps and other targets are dropped)."""
        if self._count == len(self._frames):
            self._frames = doubled(self._frames)
            self._tracks = doubled(self._tracks)
        row = self._count
        self._frames[row] = outcome.frame_index
        self._tracks[row] = np.nan  # landmarks without a result stay NaN
        for landmark, result in outcome.landmark_tracks.items():
            column = self._column.get(landmark)
            if column is not None:
                values = self._tracks[row, column]
                values[:4] = result.box
                values[_PEAK] = result.peak_score
                values[_ABERRANT] = 1.0 if result.aberrant else 0.0
        self.poses.append(outcome.pose)
        self.solver_inputs.append(outcome.solver)
        self._count += 1

    def __len__(self) -> int:
        return self._count

    @property
    def frame_indices(self) -> np.ndarray:
        """The frames appended, in order."""
        return self._frames[: self._count].copy()

    def track(self, row: int, landmark_id: str) -> tuple[Box, float, bool] | None:
        """(box, peak score, aberrant) of a landmark's target on the `row`-th frame appended
        (None: it had no result there)."""
        values = self._tracks[row, self._column[landmark_id]]
        if np.isnan(values[_ABERRANT]):
            return None
        x, y, w, h = (float(v) for v in values[:4])
        return (x, y, w, h), float(values[_PEAK]), bool(values[_ABERRANT])

    def image_points(self, row: int) -> dict[str, tuple[float, float]]:
        """Landmark id -> the point given to the pose solver on the `row`-th frame (the box
        centre when no solver input was kept), as `FrameOutcome.image_points`."""
        solver = self.solver_inputs[row]
        if solver is not None:
            return dict(solver.points)
        points = {}
        for landmark_id in self.landmark_ids:
            track = self.track(row, landmark_id)
            if track is not None:
                x, y, w, h = track[0]
                points[landmark_id] = (x + w / 2.0, y + h / 2.0)
        return points

    def refined(self, row: int) -> dict[str, bool]:
        """Landmark id -> whether the refined point replaced the box centre on that frame."""
        solver = self.solver_inputs[row]
        return {} if solver is None else dict(solver.refined)

    def events(self, row: int) -> dict[str, str]:
        """Landmark id -> what happened to it beyond tracking on that frame."""
        solver = self.solver_inputs[row]
        return {} if solver is None else dict(solver.events)
