"""Starting targets from a sequence's ground truth, and the views of the targets' scores against it: the one box of a benchmark sequence's
groundtruth_rect.txt (the target scored against it), or every landmark's box of the
per-landmark groundtruth/ a generated sequence (the demo) ships.

Functions on `autotrack_studio.controller.TabController`'s public interface (`truth`, `landmark_truth`,
`truth_target`, `cursor`, `config`, `message`, `tracker`, `require_run`, `stop_playing`,
`claim_recording`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from autotrack.errors import InputError
from autotrack.pipeline import TrackedTarget
from autotrack_studio.groundtruth import TruthView, landmark_truth_views, truth_view

if TYPE_CHECKING:
    from autotrack_studio.controller import TabController


def start_from_truth(controller: TabController) -> None:
    """Start (or restart) the ground-truth target from the current frame's ground-truth
    box; its live scores are computed against the ground truth. The first target of a
    run takes the chosen tracker preset (see choose_preset). A sequence with per-landmark
    ground truth (the demo's groundtruth/) starts a target per landmark instead."""
    if controller.truth is None and controller.landmark_truth:
        return _start_from_landmark_truth(controller)
    if controller.truth is None:
        raise InputError("this sequence has no groundtruth_rect.txt or groundtruth/")
    controller.tracker.follow()
    run = controller.require_run()
    row = controller.truth[controller.cursor]
    if not (np.isfinite(row).all() and row[2] > 0 and row[3] > 0):
        raise InputError(f"the ground truth has no box on frame {controller.cursor + 1}")
    controller.stop_playing()
    box = (float(row[0]), float(row[1]), float(row[2]), float(row[3]))
    if controller.truth_target in run.targets:
        run.place_box(controller.truth_target, controller.cursor, box)
    else:
        if len(run.targets) >= controller.config.max_targets:
            raise InputError("already the maximum number of targets: delete one first")
        controller.truth_target = run.add_target(controller.cursor, box, None)
    controller.message = (
        f"{controller.truth_target} started from the ground truth at frame {controller.cursor + 1}; "
        f"its scores grow as it tracks (Debugging → Ground truth). {controller.tracker.note()}"
    ).strip()
    controller.claim_recording()


def _start_from_landmark_truth(controller: TabController) -> None:
    """Every landmark's ground-truth box on the current frame: the target tied to it
    restarts there, a landmark without one gets a new target."""
    boxes = {}
    for landmark_id, rows in controller.landmark_truth.items():
        row = rows[controller.cursor]
        if np.isfinite(row).all() and row[2] > 0 and row[3] > 0:
            boxes[landmark_id] = (float(row[0]), float(row[1]), float(row[2]), float(row[3]))
    if not boxes:
        raise InputError(f"the ground truth has no box on frame {controller.cursor + 1}")
    controller.stop_playing()
    controller.tracker.follow()
    run = controller.require_run()
    tied = {t.landmark_id: t.id for t in run.targets.values() if t.landmark_id is not None}
    new = {lid: box for lid, box in boxes.items() if lid not in tied}
    if len(run.targets) + len(new) > controller.config.max_targets:
        raise InputError(
            f"{len(new)} more targets would pass the maximum ({controller.config.max_targets}): "
            "delete some first"
        )
    for landmark_id, box in boxes.items():
        if landmark_id in tied:
            run.place_box(tied[landmark_id], controller.cursor, box)
    if new:
        run.add_targets(controller.cursor, new)
    controller.message = (
        f"{len(boxes)} targets started from the landmarks' ground truth at frame "
        f"{controller.cursor + 1}; their scores grow as they track (Debugging → Ground truth). "
        f"{controller.tracker.note()}"
    ).strip()
    controller.claim_recording()


def truth_views(controller: TabController) -> tuple[TruthView, ...]:
    """The ground truth on the current frame and the scores of the targets against it:
    the target started from groundtruth_rect.txt (else T1), or each landmark's target."""
    run = controller.run
    if run is None:
        return ()
    if controller.truth is not None:
        return (truth_view(controller.truth, controller.cursor, scored_target(controller)),)
    return landmark_truth_views(controller.landmark_truth, run.targets, controller.cursor)


def scored_target(controller: TabController) -> TrackedTarget | None:
    """The target scored against the ground truth: the one started from it, else T1."""
    run = controller.run
    if run is None or controller.truth is None:
        return None
    return run.targets.get(controller.truth_target or "T1")
