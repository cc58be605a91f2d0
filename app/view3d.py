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

from autotrack.localization.scene import Scene
from autotrack_studio.groundtruth import PoseErrors
from autotrack_studio.views import PoseView

VALID_COLOUR = (40, 180, 60)
INVALID_COLOUR = (220, 40, 40)
GT_COLOUR = (60, 130, 240)
"""Blue, wider than the green estimate and dashed (GT_DASH), so an estimate lying on the ground
truth shows."""
GT_THICKNESS = 7.0
TRAJECTORY_THICKNESS = 2.5
GT_DASH = (2, 4)
"""The ground truth is drawn as dashes: 2 frame-to-frame segments of every 4. The estimate runs
along it within millimetres, and two lines at one depth hide each other at random (the wider
ground truth hid nearly all of the estimate), so the estimate shows in the gaps."""
LANDMARK_COLOUR = (255, 140, 0)
UP_AXIS = np.array([0.0, 0.0, 1.0])
"""The scenes' world frame has +z up."""
DEFAULT_FOV = np.radians(50.0)
"""Vertical view angle assumed until the browser reports its camera's."""
FRAME_MARGIN = 0.9
"""The framed points keep within this fraction of the view's half-width and half-height."""
NEAR_FRACTION = 0.15
"""The eye stays at least this fraction of the points' spread behind the nearest point."""


def wxyz_from_rotation(rotation: np.ndarray) -> np.ndarray:
    """A rotation matrix as viser's (w, x, y, z) quaternion."""
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    return np.array([w, x, y, z])


def framing_eye(
    points: np.ndarray,
    centre: np.ndarray,
    direction: np.ndarray,
    fov: float,
    aspect: float,
    margin: float = FRAME_MARGIN,
) -> np.ndarray:
    """The eye on the line from `centre` along `direction` (+z up), as close as it can be with
    every point inside `margin` of a perspective view looking at `centre`: vertical angle
    `fov` (radians), width / height `aspect`. A point q off the centre lies at depth
    D + q.f (f the viewing direction, D the eye's distance) and must keep |q.r| <= tan_x *
    depth and |q.u| <= tan_y * depth, so D is the largest |q.r| / tan_x - q.f, |q.u| /
    tan_y - q.f over the points; no nearer than NEAR_FRACTION of their spread past the
    nearest one."""
    back = np.asarray(direction, dtype=np.float64)
    back = back / np.linalg.norm(back)
    forward = -back
    right = np.cross(forward, UP_AXIS)
    right = right / np.linalg.norm(right)
    up = np.cross(right, forward)
    tan_y = np.tan(fov / 2.0) * margin
    tan_x = tan_y * aspect
    offsets = np.asarray(points, dtype=np.float64) - centre
    depth_offsets = offsets @ forward
    needed = np.maximum(np.abs(offsets @ right) / tan_x, np.abs(offsets @ up) / tan_y)
    spread = float(np.linalg.norm(np.ptp(offsets, axis=0))) if len(offsets) else 1.0
    distance = max(
        float(np.max(needed - depth_offsets)),
        float(np.max(-depth_offsets)) + NEAR_FRACTION * max(spread, 0.5),
    )
    return centre + back * distance


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


def dashes(segments: np.ndarray, drawn: int, period: int) -> np.ndarray:
    """The first `drawn` segments of every `period`."""
    return segments[np.arange(len(segments)) % period < drawn]


class SceneView:
    """Nodes of one tab's 3-D scene for one localisation scene."""

    def __init__(self, scene_api: viser.SceneApi) -> None:
        self.api = scene_api
        self.scene: Scene | None = None
        self._fov = 1.0
        self._aspect = 16 / 9
        self._scale = 0.3
        self._frustum_scale = 0.18
        self._first_camera: np.ndarray | None = None
        self._gt_positions: np.ndarray | None = None
        self.segments_sent = 0
        """Trajectory segments in the last update (a count the tests can check)."""
        self.trajectory_drawn = np.zeros((0, 3))
        """Positions of the trajectory drawn last (raw or smoothed, per the Display toggle)."""
        self.frustum_state = "none"
        """'valid', 'invalid' or 'none': how the current camera was drawn last."""

    def clear(self) -> None:
        """Remove everything this view added."""
        self.api.remove_by_name("/studio")
        self.scene = None
        self.segments_sent = 0
        self.trajectory_drawn = np.zeros((0, 3))
        self.frustum_state = "none"

    def show_scene(self, scene: Scene | None, gt_positions: np.ndarray | None) -> None:
        """Landmarks, world axes and the ground-truth trajectory of a newly opened sequence."""
        self.clear()
        self.api.add_frame("/studio", show_axes=False)
        self.scene = scene
        self._first_camera = (
            None if gt_positions is None or not len(gt_positions) else gt_positions[0]
        )
        self._gt_positions = gt_positions
        if scene is None:
            return
        points = np.stack([landmark.position for landmark in scene.landmarks])
        extent = float(np.ptp(points, axis=0).max()) if len(points) > 1 else 1.0
        self._scale = max(0.05, 0.08 * extent)
        # The framed view comes close to the flight: a smaller frustum leaves its path seen.
        self._frustum_scale = 0.6 * self._scale
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
                color=LANDMARK_COLOUR,
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
                dashes(segments_with_gaps(range(len(gt_positions)), gt_positions), *GT_DASH),
                colors=GT_COLOUR,
                thickness=GT_THICKNESS,
                thickness_units="screen",
            )
            self.api.add_label(
                "/studio/trajectory_gt/label", "ground truth", position=tuple(gt_positions[0])
            )

    def viewpoint(
        self,
        trajectory: np.ndarray | None = None,
        fov: float = DEFAULT_FOV,
        aspect: float = 16 / 9,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where to put the viewing camera and what to look at so the landmarks, the
        ground-truth trajectory and `trajectory` (estimated positions) fill the view of
        vertical angle `fov` (radians) and `aspect` (width / height): from behind and above the
        first ground-truth camera (else diagonally), +z up."""
        if self.scene is None:
            return np.array([-3.0, -3.0, 3.0]), np.zeros(3)
        parts = [np.stack([landmark.position for landmark in self.scene.landmarks])]
        for extra in (self._gt_positions, trajectory):
            if extra is not None and len(extra):
                parts.append(np.asarray(extra, dtype=np.float64).reshape(-1, 3))
        points = np.concatenate(parts)
        points = points[np.isfinite(points).all(axis=1)]
        centre = (points.min(axis=0) + points.max(axis=0)) / 2.0
        if self._first_camera is not None and np.linalg.norm(self._first_camera - centre) > 1e-6:
            direction = self._first_camera - centre
            direction = direction / np.linalg.norm(direction) + np.array([0.0, 0.0, 0.5])
        else:
            direction = np.array([-1.0, -1.0, 1.0])
        eye = framing_eye(points, centre, direction, fov, aspect)
        return eye, centre

    def update(self, view: PoseView, thumbnail: np.ndarray | None) -> None:
        """Draw the current camera and the estimated trajectory."""
        if self.scene is None:
            return
        segments = segments_with_gaps(view.trajectory_frames, view.trajectory_positions)
        self.segments_sent = len(segments)
        self.trajectory_drawn = view.trajectory_positions
        if len(segments):
            self.api.add_line_segments(
                "/studio/trajectory",
                segments,
                colors=VALID_COLOUR,
                thickness=TRAJECTORY_THICKNESS,
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
                scale=self._frustum_scale,
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
                scale=self._frustum_scale,
                color=INVALID_COLOUR,
                wxyz=wxyz_from_rotation(view.last_valid.rotation),
                position=tuple(view.last_valid.position),
            )
            self.frustum_state = "invalid"
        else:
            self.api.remove_by_name("/studio/camera")
            self.frustum_state = "none" if pose is None else "invalid"


def _swatch(colour: tuple[int, int, int], text: str) -> str:
    css = "#{:02x}{:02x}{:02x}".format(*colour)
    return f'<span style="color:{css}">■</span> {text}'


def view3d_legend(has_truth: bool, errors: PoseErrors | None) -> str:
    """The 3-D view's legend (what each colour is) and, with ground-truth poses, the estimate's
    error against them: ATE (RMS over the trusted frames so far) and RPE over one second."""
    items = [
        _swatch(VALID_COLOUR, "estimated trajectory and camera"),
        _swatch(INVALID_COLOUR, "camera not trusted"),
        _swatch(LANDMARK_COLOUR, "landmarks"),
    ]
    if has_truth:
        items.insert(1, _swatch(GT_COLOUR, "ground truth (dashed)"))
    text = "**3-D view**: " + " · ".join(items)
    if errors is None or not errors.frames:
        return text + ("\n\nPose error: no trusted pose yet." if has_truth else "")
    rpe = (
        f"RPE {errors.rpe_m * 1000:.1f} mm/s, {errors.rpe_deg:.2f}°/s"
        if np.isfinite(errors.rpe_m)
        else "RPE after one second of poses"
    )
    return (
        f"{text}\n\n**Pose error** vs poses_gt.tum over {errors.frames} frames: "
        f"ATE {errors.ate_m * 1000:.1f} mm, {errors.ate_deg:.2f}° · {rpe}"
    )
