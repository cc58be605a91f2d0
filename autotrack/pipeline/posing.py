"""The pipeline's pose stage: each landmark target's image point (its box centre, or the
sub-pixel point of `localization.refine`), the out-of-view gate and re-acquisition of lost
landmarks (`localization.reacquire`), and the localiser.

Refined points are kept per target and frame as the target is tracked, so a pose re-estimated
after a correction uses the same points; a target restarted from a box (drawn, corrected,
resumed) takes its template from that box. The gate and re-acquisition follow the poses in
frame order and start afresh with the localiser. Re-acquisition restarts only a target whose
tracker is at the frame being solved (never one already tracked further, e.g. while the frames
after a correction are re-tracked).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from autotrack.localization.localizer import Localizer, LocalizerParams
from autotrack.localization.reacquire import LandmarkKeeper, ReacquireParams
from autotrack.localization.refine import (
    PointRefiner,
    RefinedPoint,
    RefineParams,
    fallback_weights,
)
from autotrack.localization.scene import Scene
from autotrack.result import PoseEstimate, TrackResult

Box = tuple[float, float, float, float]


@dataclass(frozen=True)
class LandmarkEntry:
    """One landmark target's result on the frame being solved."""

    target_id: str
    landmark_id: str
    result: TrackResult
    tracker_at_frame: bool
    """True when the target's tracker is at this frame (it may be restarted here)."""


@dataclass(frozen=True)
class SolverInput:
    """What the solver was given on one frame, per landmark id."""

    points: dict[str, tuple[float, float]] = field(default_factory=dict)
    """The image point given to the solver (refined point or box centre; NaN: gated)."""
    refined: dict[str, bool] = field(default_factory=dict)
    """Whether the refined point replaced the box centre (only with refinement on)."""
    events: dict[str, str] = field(default_factory=dict)
    """What happened to the landmark beyond tracking ("out of view", "re-acquired ...")."""


@dataclass(frozen=True)
class Restart:
    """A lost landmark found again: its target's tracker restarts from `box` on this frame."""

    target_id: str
    landmark_id: str
    box: Box
    match: float


class PoseStage:
    """Points, gate, localiser and re-acquisition of one pipeline with a scene.

    `refine_params` turns on sub-pixel refinement, `reacquire_params` the out-of-view gate and
    re-acquisition (which needs the refiner's templates, so it turns refinement on with default
    settings if needed). Without either, the solver gets the box centres.
    """

    def __init__(
        self,
        scene: Scene,
        localizer_params: LocalizerParams | None = None,
        refine_params: RefineParams | None = None,
        reacquire_params: ReacquireParams | None = None,
    ) -> None:
        if reacquire_params is not None and refine_params is None:
            refine_params = RefineParams()
        self.localizer = Localizer(scene, localizer_params or LocalizerParams())
        self.refine_params = refine_params
        self._refiner = PointRefiner(refine_params) if refine_params is not None else None
        self._keeper = (
            LandmarkKeeper(scene, reacquire_params) if reacquire_params is not None else None
        )
        self._points: dict[str, dict[int, RefinedPoint]] = {}
        self._template_boxes: dict[str, Box] = {}
        self._inputs: dict[int, SolverInput] = {}
        self.last_frame = -1
        """Frame of the last pose solved since the last reset (-1: none)."""

    @property
    def reacquiring(self) -> bool:
        """True when lost landmarks are looked for after each pose."""
        return self._keeper is not None

    # -- points -------------------------------------------------------------------------------

    def start(
        self,
        frame_index: int,
        frame: np.ndarray,
        boxes: Mapping[str, Box],
        landmarks: Mapping[str, str | None],
    ) -> None:
        """Targets (re)started from `boxes` on this frame: templates from the boxes, whose
        centres are their points here; their later points are dropped."""
        if self._refiner is None:
            return
        for target_id, box in boxes.items():
            self.drop_points(target_id, frame_index)
            point = self._refiner.set_template(target_id, frame, box)
            self._points.setdefault(target_id, {})[frame_index] = point
            self._template_boxes[target_id] = tuple(box)
            landmark = landmarks.get(target_id)
            if self._keeper is not None and landmark is not None:
                self._keeper.forget(landmark)

    def refine(self, frame_index: int, frame: np.ndarray, boxes: Mapping[str, Box]) -> None:
        """Refined points of the targets tracked onto this frame (`boxes`: their boxes)."""
        if self._refiner is None or not boxes:
            return
        for target_id, box in boxes.items():
            point = self._refiner.refine_one(frame, target_id, box)
            self._points.setdefault(target_id, {})[frame_index] = point

    def drop_points(self, target_id: str, first: int) -> None:
        """Forget a target's points from frame `first` on."""
        points = self._points.get(target_id, {})
        for index in [index for index in points if index >= first]:
            del points[index]

    def remove(self, target_id: str, landmark_id: str | None) -> None:
        """A target is gone (deleted) or no longer localises `landmark_id`."""
        self._points.pop(target_id, None)
        if self._keeper is not None and landmark_id is not None:
            self._keeper.forget(landmark_id)

    def landmark_changed(self, target_id: str, old: str | None, new: str | None) -> None:
        """A target localises `new` instead of `old`: both landmarks' sizes are measured
        again, and the target's next refinement starts from its tracker's box (it was not
        refined while it localised no landmark)."""
        if self._keeper is not None:
            for landmark_id in (old, new):
                if landmark_id is not None:
                    self._keeper.forget(landmark_id)
        if self._refiner is not None:
            self._refiner.restart(target_id)

    # -- poses --------------------------------------------------------------------------------

    def reset(self) -> None:
        """Start afresh: no continuity prior, no gate, no lost-frame counts."""
        self.localizer.reset()
        if self._keeper is not None:
            self._keeper.reset()
        self.last_frame = -1

    def forget_from(self, first_stale: int) -> None:
        """Poses from `first_stale` on are being re-estimated."""
        for index in [index for index in self._inputs if index >= first_stale]:
            del self._inputs[index]
        if self.last_frame >= first_stale:
            self.reset()

    def solver_input(self, frame_index: int) -> SolverInput | None:
        """What the solver was given on a frame (None: no pose solved there)."""
        return self._inputs.get(frame_index)

    def estimate(
        self, frame_index: int, previous: int, entries: Iterable[LandmarkEntry]
    ) -> PoseEstimate:
        """The pose of `frame_index` (`previous`: the frame the sequence came from)."""
        if self.last_frame != previous:
            self.reset()
        entries = list(entries)
        solver = SolverInput()
        for entry in entries:
            found = self._points.get(entry.target_id, {}).get(frame_index)
            point = found.point if found is not None else entry.result.center
            solver.points[entry.landmark_id] = point
            if self._refiner is not None:
                solver.refined[entry.landmark_id] = found is not None and found.refined
        if self._keeper is not None:
            for landmark_id, why in self._keeper.out_of_view(frame_index).items():
                if landmark_id in solver.points:
                    solver.points[landmark_id] = (math.nan, math.nan)
                    solver.events[landmark_id] = why
        pose = self.localizer.estimate(
            frame_index,
            solver.points,
            confidences={e.landmark_id: float(e.result.peak_score) for e in entries},
            aberrant={e.landmark_id: bool(e.result.aberrant) for e in entries},
            landmark_weights=fallback_weights(solver.refined, self.refine_params),
        )
        self.last_frame = frame_index
        self._inputs[frame_index] = solver
        return pose

    def reacquire(
        self,
        frame_index: int,
        frame: np.ndarray,
        pose: PoseEstimate,
        entries: Iterable[LandmarkEntry],
    ) -> list[Restart]:
        """Lost landmarks found again where `pose` predicts them (after `estimate`); each
        restart is noted among the frame's events and the localiser forgets the landmark's
        peak history. The caller restarts the trackers."""
        if self._keeper is None or self._refiner is None:
            return []
        targets = {e.landmark_id: e for e in entries}
        first_boxes, templates = {}, {}
        for landmark_id, entry in targets.items():
            box = self._template_boxes.get(entry.target_id)
            if box is not None and self._refiner.has_template(entry.target_id):
                first_boxes[landmark_id] = box
                if entry.tracker_at_frame:
                    templates[landmark_id] = self._refiner.template_of(entry.target_id)
        restarts = []
        found = self._keeper.observe(frame_index, frame, pose, first_boxes, templates)
        for again in found:
            entry = targets[again.landmark_id]
            self._refiner.restart(entry.target_id)
            self.localizer.forget_landmark(again.landmark_id)
            u, v = again.box[0] + again.box[2] / 2, again.box[1] + again.box[3] / 2
            solver = self._inputs.get(frame_index)
            if solver is not None:
                solver.events[again.landmark_id] = (
                    f"re-acquired at ({u:.1f}, {v:.1f}), match {again.match:.2f}"
                )
            restarts.append(Restart(entry.target_id, again.landmark_id, again.box, again.match))
        return restarts
