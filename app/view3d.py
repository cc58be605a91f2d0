"""The tab's 3-D view: world axes, landmarks, the camera frustum and the trajectories.

Poses are camera-to-world in OpenCV's camera convention, which is viser's frustum convention.
A frame whose pose is invalid shows no green frustum: the last trusted pose is drawn in red,
without the frame thumbnail, and the trajectory line has a gap there.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import viser
from scipy.spatial.transform import Rotation

from app.views import PoseView
from autotrack.localization.scene import Scene

VALID_COLOUR = (40, 180, 60)
INVALID_COLOUR = (220, 40, 40)
GT_COLOUR = (120, 120, 120)


def wxyz_from_rotation(rotation: np.ndarray) -> np.ndarray:
    """A rotation matrix as viser's (w, x, y, z) quaternion."""
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    return np.array([w, x, y, z])


def segments_with_gaps(frames: Sequence[int], positions: np.ndarray) -> np.ndarray:
    """Line segments (n, 2, 3) joining positions of consecutive frame indices only, so a
    missing (invalid) frame leaves a gap."""
    frames_array = np.asarray(frames)
    if len(frames_array) < 2:
        return np.zeros((0, 2, 3))
    joined = np.diff(frames_array) == 1
    starts = positions[:-1][joined]
    ends = positions[1:][joined]
    return np.stack([starts, ends], axis=1)


class SceneView:
    """Nodes of one tab's 3-D scene for one localisation scene."""

    def __init__(self, scene_api: viser.SceneApi) -> None:
        self.api = scene_api
        self.scene: Scene | None = None
        self._fov = 1.0
        self._aspect = 16 / 9
        self._scale = 0.3
        self._first_camera: np.ndarray | None = None
        self.segments_sent = 0
        """Trajectory segments in the last update (a count the tests can check)."""
        self.frustum_state = "none"
        """'valid', 'invalid' or 'none': how the current camera was drawn last."""

    def clear(self) -> None:
        """Remove everything this view added."""
        self.api.remove_by_name("/studio")
        self.scene = None
        self.segments_sent = 0
        self.frustum_state = "none"

    def show_scene(self, scene: Scene | None, gt_positions: np.ndarray | None) -> None:
        """Landmarks, world axes and the ground-truth trajectory of a newly opened sequence."""
        self.clear()
        self.api.add_frame("/studio", show_axes=False)
        self.scene = scene
        self._first_camera = (
            None if gt_positions is None or not len(gt_positions) else gt_positions[0]
        )
        if scene is None:
            return
        points = np.stack([landmark.position for landmark in scene.landmarks])
        extent = float(np.ptp(points, axis=0).max()) if len(points) > 1 else 1.0
        self._scale = max(0.05, 0.08 * extent)
        camera = scene.camera
        self._fov = float(2.0 * np.arctan2(camera.height / 2.0, camera.fy))
        self._aspect = camera.width / camera.height
        self.api.add_frame(
            "/studio/world", axes_length=2 * self._scale, axes_radius=0.05 * self._scale
        )
        for landmark in scene.landmarks:
            self.api.add_icosphere(
                f"/studio/landmarks/{landmark.id}",
                radius=0.4 * self._scale,
                color=(255, 140, 0),
                position=tuple(landmark.position),
            )
            self.api.add_label(
                f"/studio/landmarks/{landmark.id}/label",
                landmark.name or landmark.id,
                position=(0.0, 0.0, 0.4 * self._scale),
            )
        if gt_positions is not None and len(gt_positions) > 1:
            self.api.add_line_segments(
                "/studio/trajectory_gt",
                segments_with_gaps(range(len(gt_positions)), gt_positions),
                colors=GT_COLOUR,
                thickness=2.0,
                thickness_units="screen",
            )

    def viewpoint(self) -> tuple[np.ndarray, np.ndarray]:
        """Where to put the viewing camera and what to look at: behind and above the first
        ground-truth camera position (else diagonally off the landmarks), +z up."""
        if self.scene is None:
            return np.array([-3.0, -3.0, 3.0]), np.zeros(3)
        points = np.stack([landmark.position for landmark in self.scene.landmarks])
        centre = points.mean(axis=0)
        extent = float(max(1.0, np.linalg.norm(np.ptp(points, axis=0))))
        if self._first_camera is not None:
            back = self._first_camera - centre
            eye = centre + 1.6 * back + np.array([0.0, 0.0, 0.6 * extent])
        else:
            eye = centre + np.array([-1.0, -1.0, 1.0]) * extent
        return eye, centre

    def update(self, view: PoseView, thumbnail: np.ndarray | None) -> None:
        """Draw the current camera and the estimated trajectory."""
        if self.scene is None:
            return
        segments = segments_with_gaps(view.trajectory_frames, view.trajectory_positions)
        self.segments_sent = len(segments)
        if len(segments):
            self.api.add_line_segments(
                "/studio/trajectory",
                segments,
                colors=VALID_COLOUR,
                thickness=3.0,
                thickness_units="screen",
            )
        else:
            self.api.remove_by_name("/studio/trajectory")
        pose = view.pose
        if pose is not None and pose.valid:
            self.api.add_camera_frustum(
                "/studio/camera",
                fov=self._fov,
                aspect=self._aspect,
                scale=self._scale,
                color=VALID_COLOUR,
                image=thumbnail,
                format="jpeg",
                jpeg_quality=70,
                wxyz=wxyz_from_rotation(pose.rotation),
                position=tuple(pose.position),
            )
            self.frustum_state = "valid"
        elif view.last_valid is not None:
            self.api.add_camera_frustum(
                "/studio/camera",
                fov=self._fov,
                aspect=self._aspect,
                scale=self._scale,
                color=INVALID_COLOUR,
                wxyz=wxyz_from_rotation(view.last_valid.rotation),
                position=tuple(view.last_valid.position),
            )
            self.frustum_state = "invalid"
        else:
            self.api.remove_by_name("/studio/camera")
            self.frustum_state = "none" if pose is None else "invalid"
