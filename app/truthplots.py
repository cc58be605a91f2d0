"""The Ground truth tab: the running P@20 and AUC of the target scored against the ground
truth, and its centre error and overlap per frame (live uPlot charts, the current frame
marked as on the signal charts)."""

from __future__ import annotations

import numpy as np
import viser
import viser.uplot

from autotrack.evaluation.metrics import PRECISION_SCORE_THRESHOLD
from autotrack_studio.groundtruth import PoseErrors, TruthView
from autotrack_studio.plots import (
    CHART_PADDING,
    EMPTY_SCALES,
    chart_data,
    cursor_series,
    line_series,
    send_data,
    x_range,
)


def scores_text(truth: TruthView | None, truths: tuple[TruthView, ...] = ()) -> str:
    """The scores as the tab shows them (markdown): the charted target's, and with several
    targets scored (the demo's landmarks) a table of them all."""
    if truth is None:
        return "This sequence has no ground-truth boxes (groundtruth_rect.txt or groundtruth/)."
    if truth.frames is None:
        return (
            "No target to score yet: *Targets → Start from ground truth* starts from this "
            "frame's ground-truth boxes (or the targets drawn are scored)."
        )
    first, last = truth.frames
    text = (
        f"**{truth.target_id}** against the ground truth, frames {first + 1}-{last + 1} "
        f"({last - first + 1} frames): **P@20 = {truth.precision:.3f}**, "
        f"**AUC = {truth.auc:.3f}** (as `autotrack track` scores the same frames)."
    )
    scored = [view for view in truths if view.frames is not None]
    if len(scored) < 2:
        return text
    rows = ["| target | ground truth | frames | P@20 | AUC |", "|---|---|---|---|---|"]
    for view in scored:
        first, last = view.frames
        rows.append(
            f"| {view.target_id} | {view.label} | {first + 1}-{last + 1} | "
            f"{view.precision:.3f} | {view.auc:.3f} |"
        )
    charted = "the charts show the target chosen in *Drag draws*, else the first"
    return f"{text}\n\n" + "\n".join(rows) + f"\n\n({charted}.)"


def pose_error_text(errors: PoseErrors | None) -> str:
    """The camera's error against poses_gt.tum (markdown; '' without one)."""
    if errors is None:
        return ""
    if not errors.frames:
        return "**Camera pose** vs poses_gt.tum: no trusted pose yet."
    rpe = (
        f"RPE over 1 s **{errors.rpe_m * 1000:.1f} mm**, {errors.rpe_deg:.2f}°"
        if np.isfinite(errors.rpe_m)
        else "RPE once poses span a second"
    )
    return (
        f"**Camera pose** vs poses_gt.tum over {errors.frames} trusted frames: "
        f"ATE **{errors.ate_m * 1000:.1f} mm**, {errors.ate_deg:.2f}° (RMS) · {rpe}."
    )


class TruthPlots:
    """The scores line and the centre-error and IoU charts."""

    def __init__(self, gui: viser.GuiApi, container: viser.GuiTabHandle) -> None:
        self.gui = gui
        with container:
            self.scores = gui.add_markdown(scores_text(None))
            self.poses = gui.add_markdown("")
            empty = np.zeros(1)
            frame = viser.uplot.Series(label="frame")
            self.error = gui.add_uplot(
                data=(empty, empty, empty, empty),
                series=(
                    frame,
                    line_series("centre error (px)", "#e8590c"),
                    line_series("20 px", "#868e96", dash=(6.0, 4.0)),
                    cursor_series(),
                ),
                title="Centre error (px)",
                aspect=2.0,
                padding=CHART_PADDING,
                scales=EMPTY_SCALES,
            )
            self.iou = gui.add_uplot(
                data=(empty, empty, empty),
                series=(frame, line_series("IoU", "#1971c2"), cursor_series()),
                title="Overlap (IoU)",
                aspect=2.0,
                padding=CHART_PADDING,
                scales=EMPTY_SCALES,
            )
        self._scales: tuple | None = None
        self.last_text = ""

    def update(
        self,
        truth: TruthView | None,
        cursor: int,
        truths: tuple[TruthView, ...] = (),
        pose_errors: PoseErrors | None = None,
    ) -> None:
        """Show the scores of `truths`, `truth`'s per-frame values up to its last scored
        frame, and the camera's pose error."""
        text = scores_text(truth, truths)
        if text != self.last_text:
            self.scores.content = text
            self.last_text = text
        poses = pose_error_text(pose_errors)
        if poses != self.poses.content:
            self.poses.content = poses
        if truth is None or truth.frames is None:
            return
        count = max(truth.frames[1], cursor) + 1
        errors = np.where(np.isfinite(truth.errors[:count]), truth.errors[:count], np.nan)
        finite = errors[np.isfinite(errors)]
        top = max(2.0 * PRECISION_SCORE_THRESHOLD, float(finite.max()) * 1.1 if finite.size else 0)
        x_scale = {"time": False, "auto": False, "range": x_range(count - 1, len(truth.errors))}
        scales = (x_scale, top)
        if scales != self._scales:
            self.error.scales = {"x": x_scale, "y": {"auto": False, "range": (0.0, top)}}
            self.iou.scales = {"x": x_scale, "y": {"auto": False, "range": (0.0, 1.0)}}
            self._scales = scales
        threshold = np.full(count, PRECISION_SCORE_THRESHOLD)
        send_data(self.error, chart_data(count, [errors, threshold], cursor, (0.0, top)))
        send_data(self.iou, chart_data(count, [truth.ious[:count]], cursor, (0.0, 1.0)))
