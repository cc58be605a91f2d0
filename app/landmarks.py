"""Which target is which scene landmark: boxes drawn in any order are tied by the library's
correspondence search (autotrack.localization.pnp.rank_correspondences), and ties chosen by
hand are kept. No viser here; the controller calls it and the panels show `LandmarkTies`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from autotrack.errors import InputError
from autotrack.io.boxes_json import read_boxes_json
from autotrack.localization.pnp import Correspondence, boxes_by_landmark, rank_correspondences
from autotrack.pipeline import Pipeline

if TYPE_CHECKING:
    from autotrack_studio.boxes import Box
    from autotrack_studio.controller import TabController

MIN_POINTS = 4
"""The search needs four boxes (P3P on three, the fourth to check)."""


@dataclass(frozen=True)
class Assignment:
    """The outcome of one correspondence search."""

    frame_index: int
    target_ids: tuple[str, ...]
    """Targets searched, in the order of the search's image points."""
    found: Correspondence | None
    """None: no assignment puts the landmarks in front of the camera (or degenerate boxes)."""

    @property
    def residuals(self) -> dict[str, float]:
        """Target id -> reprojection error (px) of its box centre under the assignment."""
        if self.found is None or not self.found.plausible:
            return {}
        return {
            self.target_ids[row]: self.found.errors[landmark]
            for landmark, row in self.found.assignment.items()
        }

    @property
    def warning(self) -> str:
        """'' when the assignment is clear, else what is wrong (markdown)."""
        found = self.found
        if found is None or not found.plausible:
            best = "" if found is None else f" (the best reprojects at {found.rms:.1f} px RMS)"
            return (
                f"⚠ **Implausible**: no assignment of these {len(self.target_ids)} boxes to the "
                f"landmarks reprojects within {self.limit:g} px{best}. The ties were not "
                "changed: check the boxes, or choose each target's landmark by hand."
            )
        if found.ambiguous:
            return (
                f"⚠ **Ambiguous**: another assignment fits almost as well "
                f"({found.runner_up_rms:.1f} px against {found.rms:.1f} px RMS). Check the "
                "labels on the frame and choose a target's landmark by hand if one is wrong."
            )
        return ""

    @property
    def limit(self) -> float:
        return 5.0 if self.found is None else self.found.max_error_px


@dataclass
class LandmarkTies:
    """The ties a tab's user chose by hand, and the last search's outcome."""

    manual: set[str] = field(default_factory=set)
    """Targets whose landmark the user chose: the search leaves them alone."""
    last: Assignment | None = None

    def forget(self, target_id: str) -> None:
        """A target was deleted."""
        self.manual.discard(target_id)
        if self.last is not None and target_id in self.last.target_ids:
            self.last = None

    def search(self, run: Pipeline, frame_index: int) -> Assignment | None:
        """Tie the targets with a box on `frame_index` (except hand-tied ones) to the free
        landmarks by the correspondence search, when there are at least four of them; the
        ties change only when the best assignment is plausible. Returns the outcome (None:
        no search, too few boxes)."""
        scene = run.scene
        if scene is None:
            return None
        targets = [
            t for t in run.targets.values() if t.id not in self.manual and frame_index in t.results
        ]
        held = {t.landmark_id for t in run.targets.values() if t.id in self.manual}
        free = [landmark for landmark in scene.landmark_ids if landmark not in held]
        if len(targets) < MIN_POINTS or len(targets) > len(free):
            return None
        centres = [t.results[frame_index].center for t in targets]
        found = rank_correspondences(centres, scene, landmark_ids=free)
        assignment = Assignment(frame_index, tuple(t.id for t in targets), found)
        self.last = assignment
        if found is not None and found.plausible:
            wanted = {targets[row].id: landmark for landmark, row in found.assignment.items()}
            changed = [t for t in targets if t.landmark_id != wanted.get(t.id)]
            for target in changed:  # untie first: a landmark belongs to one target at a time
                run.assign_landmark(target.id, None, frame_index)
            for target in changed:
                run.assign_landmark(target.id, wanted.get(target.id), frame_index)
        return assignment

    def tie_by_hand(
        self, run: Pipeline, target_id: str, landmark_id: str | None, frame_index: int
    ) -> str | None:
        """Tie `target_id` to `landmark_id` as the user chose; a target holding that landmark
        takes this one's old landmark (a swap). Returns the other target's id, if swapped."""
        target = run.targets[target_id]
        holder = next(
            (
                other
                for other in run.targets.values()
                if landmark_id is not None
                and other.landmark_id == landmark_id
                and other.id != target_id
            ),
            None,
        )
        previous = target.landmark_id
        if holder is not None:
            run.assign_landmark(holder.id, None, frame_index)
        run.assign_landmark(target_id, landmark_id, frame_index)
        self.manual.add(target_id)
        if holder is None:
            return None
        run.assign_landmark(holder.id, previous, frame_index)
        self.manual.add(holder.id)
        return holder.id


def search_message(run: Pipeline, outcome: Assignment | None) -> str:
    """What to tell the user after a search (' ...', to follow the drawing message)."""
    if outcome is None:
        free = run.free_landmarks()
        if run.scene is None or not free:
            return ""
        tied = len(run.scene.landmarks) - len(free)
        return f" Landmarks are tied once four boxes are drawn ({tied} tied, {len(free)} to draw)."
    if outcome.warning:
        return " " + outcome.warning
    ties = ", ".join(f"{tid} → {run.targets[tid].landmark_id}" for tid in outcome.target_ids)
    return f" Landmarks by the correspondence search: {ties}."


def load_boxes_json(controller: TabController) -> None:
    """Place the boxes of the controller's sequence's boxes.json on frame 1, one target per
    landmark (a list of boxes is assigned to landmarks by the correspondence search); the
    first target of a run takes the chosen tracker preset."""
    boxes_json_boxes(controller, "this sequence has no boxes.json")  # refused before reopening
    controller.stop_playing()
    controller.tracker.follow()
    run = controller.require_run()
    boxes = boxes_json_boxes(controller, "this sequence has no boxes.json")
    controller.cursor = 0
    run.add_targets(0, boxes)
    controller.message = f"Loaded {len(boxes)} boxes from boxes.json on frame 1."
    controller.claim_recording()


def boxes_json_boxes(controller: TabController, missing: str) -> dict[str, Box]:
    """The boxes.json boxes by landmark, for a run with no target yet (file or live; `missing`:
    the message when there is no boxes.json or no scene)."""
    run = controller.require_run()
    if controller.boxes_path is None or run.scene is None:
        raise InputError(missing)
    if run.targets:  # it adds a target per landmark: more would pass the cap, or stack
        raise InputError(
            f"boxes.json adds a target for every landmark: delete the {len(run.targets)} "
            "drawn first, or draw the rest by hand"
        )
    return boxes_by_landmark(read_boxes_json(controller.boxes_path), run.scene)
