"""The Targets table of a tab: the scene's landmarks, each target's tie, reprojection residual,
box and last tracked frame, which tracker the hybrid trusted on the current frame, and the
landmark search's warning (markdown for a viser widget)."""

from __future__ import annotations

import math

from autotrack.hybrid.factory import trusted_of
from autotrack_studio.boxes import Box
from autotrack_studio.controller import TabController


def compact_box(box: Box) -> str:
    """A box as the Targets table shows it: each value to 0.1 px without trailing zeros."""
    return ", ".join(f"{round(value, 1):g}" for value in box)


def _residuals_at_cursor(controller: TabController) -> dict[str, float]:
    """Target id -> reprojection error (px) of its box centre: under the current frame's pose
    for a target whose landmark the pose reprojected, else under the last correspondence
    search's assignment (targets tied by a boxes file or a reopened session have no search)."""
    last = controller.ties.last
    residuals = {} if last is None else dict(last.residuals)
    run = controller.run
    pose = None if run is None else run.poses.get(controller.cursor)
    if pose is None:
        return residuals
    for target in controller.targets():
        error = pose.reprojection_errors.get(target.landmark_id or "", math.nan)
        if math.isfinite(error):
            residuals[target.id] = error
    return residuals


def targets_table(controller: TabController) -> str:
    """The scene's landmarks (tied, or still to draw), the targets (`T1 → A`: tied to landmark
    A; `*`: by hand) with their reprojection residual (`_residuals_at_cursor`), the box on the
    current frame and the last frame tracked, under it which tracker the hybrid trusted on the
    current frame (`both`, `filter`, `siamese`), and the last landmark search's warning. Narrow
    enough that its header reads on one line at the default panel width (tests/test_app_browser_panels.py)."""
    run = controller.run
    targets = controller.targets()
    parts: list[str] = []
    if run is not None and run.scene is not None:
        tied = {target.landmark_id: target.id for target in targets if target.landmark_id}
        items = [
            f"- **{landmark.id}** {landmark.name or ''} "
            + (f"→ {tied[landmark.id]}" if landmark.id in tied else "· *to draw*")
            for landmark in run.scene.landmarks
        ]
        parts.append("Scene landmarks:\n\n" + "\n".join(items))
    if not targets:
        parts.append("No targets yet. Shift-drag on the frame to draw one (any order).")
        return "\n\n".join(parts)
    last = controller.ties.last
    residuals = _residuals_at_cursor(controller)
    rows = ["| target | residual | box x, y, w, h | tracked to |", "|---|---|---|---|"]
    trusted: list[str] = []
    for target in targets:
        result = target.results.get(controller.cursor)
        if trusted_of(result) is not None:
            trusted.append(f"{target.id} {trusted_of(result)}")
        box = "—" if result is None else compact_box(result.box)
        residual = residuals.get(target.id)
        landmark = "" if target.landmark_id is None else f" → {target.landmark_id}"
        by_hand = "*" if target.id in controller.ties.manual else ""
        rows.append(
            f"| {target.id}{landmark}{by_hand} | "
            f"{'—' if residual is None else f'{residual:.1f} px'} | {box} | "
            f"{target.last_frame + 1} |"
        )
    parts.append("\n".join(rows))
    if trusted:
        parts.append(f"Hybrid trusted on frame {controller.cursor + 1}: {', '.join(trusted)}")
    if controller.ties.manual & set(run.targets if run is not None else ()):
        parts.append("\\* tied to its landmark by hand")
    if last is not None and last.warning:
        parts.append(last.warning)
    return "\n\n".join(parts)
