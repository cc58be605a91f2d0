"""Keeping landmarks through occlusions and trips out of the view, and re-acquiring them.

A correlation filter cannot find its target again after a long occlusion: while the target is
hidden it either drifts onto whatever covers it or stays put, and it has no reason to come back.
The localiser, however, knows each landmark's 3-D position and (from the other landmarks) the
camera pose, so it knows where the landmark must appear:

- before each solve, a landmark whose predicted box (from the last trusted pose) is not fully
  inside the image is left out ("out of view") instead of feeding a box stuck at the border;
- after each trusted pose, a landmark that has been left out of the solve (lost, low peak,
  outlier, out of view) for `lost_frames` frames in a row is looked for where the pose predicts
  it: its first-frame appearance, scaled by the predicted depth ratio, is matched
  (`cv2.matchTemplate`, normalised correlation) in a window around the predicted point; a match
  above `min_match` restarts its tracker on the predicted-size box centred at the match. While
  the landmark is still hidden the match stays low and nothing is restarted.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import cv2
import numpy as np

from autotrack.localization.camera import project_points
from autotrack.localization.refine import to_grey
from autotrack.localization.scene import Scene

Box = tuple[float, float, float, float]


@dataclass(frozen=True)
class ReacquireParams:
    """When a landmark counts as out of view or lost, and how it is found again."""

    border_margin_px: float = 2.0
    """A landmark whose predicted box comes closer than this to the image border is out of view
    (pixels)."""
    lost_frames: int = 2
    """Consecutive frames a landmark must have been left out of the solve before a search."""
    min_match: float = 0.6
    """Smallest normalised correlation (TM_CCOEFF_NORMED, -1..1) of the scaled first-frame
    appearance at which the landmark counts as found again."""
    search_fraction: float = 0.6
    """Half-width of the search window around the predicted point, as a fraction of the predicted
    box size (the prediction is off by the pose error and one frame of motion)."""
    min_search_px: float = 12.0
    """Floor of that half-width (pixels)."""
    max_prior_age_frames: int = 10
    """The out-of-view test uses the last trusted pose only while it is at most this old."""


@dataclass(frozen=True)
class Reacquisition:
    """A landmark found again: where its tracker restarts."""

    landmark_id: str
    """The landmark."""
    box: Box
    """Restart box (x, y, w, h), 0-based pixels."""
    match: float
    """Normalised correlation of the match."""
    predicted: tuple[float, float]
    """Where the pose predicted the landmark (u, v)."""


def predicted_depths(scene: Scene, rotation: np.ndarray, position: np.ndarray) -> dict[str, float]:
    """Depth (metres along the optical axis) of every landmark for a camera-to-world pose."""
    forward = np.asarray(rotation)[:, 2]
    return {
        landmark.id: float((landmark.position - np.asarray(position)) @ forward)
        for landmark in scene.landmarks
    }


def box_inside(box: Box, width: int, height: int, margin: float) -> bool:
    """True when the whole box lies at least `margin` pixels inside a width x height image."""
    x, y, w, h = box
    return x >= margin and y >= margin and x + w <= width - margin and y + h <= height - margin


def match_scaled_template(
    frame: np.ndarray,
    template: np.ndarray,
    template_centre: tuple[float, float],
    scale: float,
    predicted: tuple[float, float],
    half_window: float,
) -> tuple[float, tuple[float, float]] | None:
    """Best normalised-correlation match of `template` (grey float32) resized by `scale` within
    `half_window` pixels of `predicted` in an RGB or grey frame (only the window is converted
    to grey): (score, matched centre) or None when the window does not fit."""
    height, width = template.shape
    size = (max(int(round(width * scale)), 8), max(int(round(height * scale)), 8))
    resized = cv2.resize(template, size, interpolation=cv2.INTER_AREA)
    sx, sy = size[0] / width, size[1] / height
    cx, cy = template_centre[0] * sx, template_centre[1] * sy
    # The window holds every template placement whose centre is within half_window.
    x0 = int(math.floor(predicted[0] - cx - half_window))
    y0 = int(math.floor(predicted[1] - cy - half_window))
    x1 = int(math.ceil(predicted[0] - cx + half_window)) + size[0]
    y1 = int(math.ceil(predicted[1] - cy + half_window)) + size[1]
    x0, y0 = max(x0, 0), max(y0, 0)
    x1, y1 = min(x1, frame.shape[1]), min(y1, frame.shape[0])
    if x1 - x0 < size[0] + 1 or y1 - y0 < size[1] + 1:
        return None
    scores = cv2.matchTemplate(to_grey(frame[y0:y1, x0:x1]), resized, cv2.TM_CCOEFF_NORMED)
    _, best, _, (bx, by) = cv2.minMaxLoc(scores)
    return float(best), (x0 + bx + cx, y0 + by + cy)


@dataclass
class LandmarkKeeper:
    """Out-of-view gating before each solve and re-acquisition after it."""

    scene: Scene
    params: ReacquireParams = field(default_factory=ReacquireParams)
    _sizes: dict[str, tuple[float, float, float]] = field(default_factory=dict, init=False)
    """Landmark id -> (box width, box height, depth) of its first box, for size prediction."""
    _missing: dict[str, int] = field(default_factory=dict, init=False)
    _pose: tuple[int, np.ndarray, np.ndarray] | None = field(default=None, init=False)

    def reset(self) -> None:
        """Forget the last pose and the lost-frame counts (the poses start afresh)."""
        self._pose = None
        self._missing.clear()

    def forget(self, landmark_id: str) -> None:
        """Forget a landmark's size and lost-frame count (its first box was replaced)."""
        self._sizes.pop(landmark_id, None)
        self._missing.pop(landmark_id, None)

    def predicted_boxes(self, rotation: np.ndarray, position: np.ndarray) -> dict[str, Box]:
        """Each landmark's box (first box size scaled by the depth ratio) where the pose puts it;
        landmarks behind the camera or never sized are left out."""
        depths = predicted_depths(self.scene, rotation, position)
        ids = [k for k in self._sizes if depths.get(k, 0.0) > 0.05]
        if not ids:
            return {}
        points = project_points(
            self.scene.camera, self.scene.object_points(ids), rotation, position
        )
        boxes = {}
        for landmark_id, (u, v) in zip(ids, points, strict=True):
            w0, h0, d0 = self._sizes[landmark_id]
            scale = d0 / depths[landmark_id]
            w, h = w0 * scale, h0 * scale
            boxes[landmark_id] = (float(u - w / 2), float(v - h / 2), w, h)
        return boxes

    def out_of_view(self, frame_index: int) -> dict[str, str]:
        """Landmarks the last trusted pose puts (partly) outside the image -> reason."""
        if self._pose is None or frame_index - self._pose[0] > self.params.max_prior_age_frames:
            return {}
        camera = self.scene.camera
        boxes = self.predicted_boxes(self._pose[1], self._pose[2])
        depths = predicted_depths(self.scene, self._pose[1], self._pose[2])
        out = {}
        for landmark_id in self._sizes:
            box = boxes.get(landmark_id)
            if depths[landmark_id] <= 0.05:
                out[landmark_id] = "out of view (behind the camera)"
            elif box is not None and not box_inside(
                box, camera.width, camera.height, self.params.border_margin_px
            ):
                out[landmark_id] = "out of view"
        return out

    def observe(
        self,
        frame_index: int,
        frame: np.ndarray,
        pose,
        first_boxes: Mapping[str, Box],
        templates: Mapping[str, tuple[np.ndarray, tuple[float, float]]],
    ) -> list[Reacquisition]:
        """After a frame's solve: remember the pose, count the frames each landmark has been left
        out, and look for those missing long enough in `frame` (RGB or grey). `first_boxes` are
        the landmarks' first boxes, `templates` their first-frame grey appearance and centre
        (refine.PointRefiner)."""
        if not pose.valid:
            return []
        params = self.params
        depths = predicted_depths(self.scene, pose.rotation, pose.position)
        for landmark_id, box in first_boxes.items():
            if landmark_id not in self._sizes and landmark_id in pose.used_landmarks:
                self._sizes[landmark_id] = (box[2], box[3], depths[landmark_id])
        self._pose = (frame_index, pose.rotation, pose.position)
        for landmark_id in self._sizes:
            if landmark_id in pose.used_landmarks:
                self._missing[landmark_id] = 0
            else:
                self._missing[landmark_id] = self._missing.get(landmark_id, 0) + 1
        camera = self.scene.camera
        boxes = self.predicted_boxes(pose.rotation, pose.position)
        found = []
        for landmark_id, missing in self._missing.items():
            box = boxes.get(landmark_id)
            if missing < params.lost_frames or box is None or landmark_id not in templates:
                continue
            if not box_inside(box, camera.width, camera.height, params.border_margin_px):
                continue
            template, centre = templates[landmark_id]
            scale = max(box[2] / template.shape[1], 1e-3)
            predicted = (box[0] + box[2] / 2, box[1] + box[3] / 2)
            half = max(params.search_fraction * max(box[2], box[3]), params.min_search_px)
            match = match_scaled_template(frame, template, centre, scale, predicted, half)
            if match is None or match[0] < params.min_match:
                continue
            score, (u, v) = match
            restart = (u - box[2] / 2, v - box[3] / 2, box[2], box[3])
            found.append(Reacquisition(landmark_id, restart, score, predicted))
            self._missing[landmark_id] = 0
        return found
