"""Camera maths in one place: the pinhole camera with OpenCV distortion, projection, and the
conversions between OpenCV's world-to-camera (rvec, tvec) and camera-to-world poses.

Poses are camera-to-world: `rotation` maps camera axes (OpenCV: x right, y down, z forward) to
world axes, `position` is the camera centre in world metres. Pixel (0, 0) is the centre of the
top-left pixel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np

from autotrack.errors import InputError


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole camera with OpenCV distortion, in pixels of a `width` x `height` image."""

    fx: float
    """Focal length along x (pixels)."""
    fy: float
    """Focal length along y (pixels)."""
    cx: float
    """Principal point x (pixels, 0-based: the top-left pixel's centre is 0)."""
    cy: float
    """Principal point y (pixels, 0-based)."""
    distortion: tuple[float, ...] = ()
    """OpenCV distortion coefficients (k1, k2, p1, p2[, k3, ...]); empty for none."""
    width: int = 0
    """Image width (pixels)."""
    height: int = 0
    """Image height (pixels)."""

    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K (float64; read-only, built once per camera: copy it to
        change it)."""
        return self._matrix

    def distortion_array(self) -> np.ndarray:
        """Distortion coefficients as a float64 array (length 0 when there is no distortion;
        read-only, built once per camera)."""
        return self._distortion

    @cached_property
    def _matrix(self) -> np.ndarray:
        # Every projection and solve of every frame passes K to OpenCV: built once, not per call.
        matrix = np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )
        matrix.flags.writeable = False
        return matrix

    @cached_property
    def _distortion(self) -> np.ndarray:
        distortion = np.array(self.distortion, dtype=np.float64)
        distortion.flags.writeable = False
        return distortion

    def check_image_size(self, width: int, height: int) -> None:
        """InputError unless this camera is calibrated for `width` x `height` images."""
        if (width, height) != (self.width, self.height):
            raise InputError(
                f"frames are {width}x{height} but the scene's camera is calibrated for "
                f"{self.width}x{self.height}: use intrinsics for this image size"
            )

    def scaled(self, factor: float) -> CameraIntrinsics:
        """The same camera for images resized by `factor` (distortion is scale-free)."""
        # Pixel centres sit at integer coordinates, so the principal point scales about -0.5.
        return CameraIntrinsics(
            fx=self.fx * factor,
            fy=self.fy * factor,
            cx=(self.cx + 0.5) * factor - 0.5,
            cy=(self.cy + 0.5) * factor - 0.5,
            distortion=self.distortion,
            width=round(self.width * factor),
            height=round(self.height * factor),
        )


def camera_pose_from_pnp(rvec: np.ndarray, tvec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rotation camera-to-world, camera centre) from OpenCV's world-to-camera rvec, tvec."""
    rotation_cw, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    # x_cam = R_cw x_world + t  =>  camera centre C = -R_cw^T t, R_wc = R_cw^T
    centre = -rotation_cw.T @ np.asarray(tvec, dtype=np.float64).reshape(3)
    return rotation_cw.T, centre


def pnp_from_camera_pose(
    rotation: np.ndarray, position: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's (rvec, tvec) from a camera-to-world rotation and camera centre."""
    rotation_cw = np.asarray(rotation, dtype=np.float64).T
    rvec, _ = cv2.Rodrigues(rotation_cw)
    tvec = -rotation_cw @ np.asarray(position, dtype=np.float64).reshape(3)
    return rvec.reshape(3), tvec


def project_points(
    camera: CameraIntrinsics, points_world: np.ndarray, rotation: np.ndarray, position: np.ndarray
) -> np.ndarray:
    """Pixel coordinates (n, 2) of world points seen by a camera at (rotation, position)."""
    rvec, tvec = pnp_from_camera_pose(rotation, position)
    projected, _ = cv2.projectPoints(
        np.asarray(points_world, dtype=np.float64).reshape(-1, 1, 3),
        rvec,
        tvec,
        camera.matrix(),
        camera.distortion_array(),
    )
    return projected.reshape(-1, 2)


def rotation_angle_deg(rotation_a: np.ndarray, rotation_b: np.ndarray) -> float:
    """Angle (degrees) of the rotation taking `rotation_a` to `rotation_b`."""
    cosine = (np.trace(rotation_a.T @ rotation_b) - 1.0) / 2.0
    return math.degrees(math.acos(float(np.clip(cosine, -1.0, 1.0))))
