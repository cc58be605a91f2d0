"""Rendering a synthetic sequence (frames and ground-truth files).

Rendering uses OpenCV only: every plane is one `cv2.warpPerspective` of a procedurally generated
texture (a mip level chosen per frame) into the bounding rectangle of its visible polygon, drawn
far to near; lens distortion is one `cv2.remap`. Each frame carries a global lighting change
(gain and gamma drift, a dimming event), sensor noise, motion blur in long-exposure bursts and
JPEG compression. Everything is seeded: the same seed gives the same bytes.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from autotrack.errors import InputError
from autotrack.io.atomic import write_image, write_text
from autotrack.io.tum import write_tum
from autotrack.localization.camera import CameraIntrinsics, project_points
from autotrack.localization.scene import Scene, save_scene
from autotrack.synthetic.trajectories import (
    SequenceSpec,
    frame_conditions,
    ground_truth_boxes,
    ground_truth_poses,
)
from autotrack.synthetic.world import (
    LANDMARK_LAYOUT,
    TexturedPlane,
    build_world,
    default_camera,
    default_scene,
    visibility_problems,
)

NEAR_PLANE_M = 0.05


def _clip_near(points_camera: np.ndarray, near: float) -> np.ndarray:
    """Sutherland-Hodgman clip of a polygon (n, 3 camera coordinates) to z >= near."""
    out = []
    count = len(points_camera)
    for k in range(count):
        current, following = points_camera[k], points_camera[(k + 1) % count]
        inside_now, inside_next = current[2] >= near, following[2] >= near
        if inside_now:
            out.append(current)
        if inside_now != inside_next:
            fraction = (near - current[2]) / (following[2] - current[2])
            out.append(current + fraction * (following - current))
    return np.array(out).reshape(-1, 3)


def _undistort_pixels(
    points: np.ndarray, matrix: np.ndarray, distortion: np.ndarray, criteria: tuple
) -> np.ndarray:
    """Undistorted pixel positions (N x 1 x 2) of distorted ones, iterated to `criteria`.

    OpenCV 4.x takes the criteria only through `undistortPointsIter` (its `undistortPoints`
    stops after 5 iterations); OpenCV 5 dropped `undistortPointsIter` and gave `undistortPoints`
    a criteria argument instead."""
    if hasattr(cv2, "undistortPointsIter"):
        return cv2.undistortPointsIter(points, matrix, distortion, None, matrix, criteria)
    return cv2.undistortPoints(points, matrix, distortion, None, None, matrix, criteria)


class Renderer:
    """Draws the world for a camera pose: pinhole render on a margin-padded canvas, then lens
    distortion, motion blur, lighting, noise. Frames are BGR uint8."""

    def __init__(self, camera: CameraIntrinsics, seed: int, noise_sigma: float = 2.5) -> None:
        self.camera = camera
        self.room, self.objects = build_world(seed)
        size = (camera.width, camera.height)
        grid = np.stack(np.meshgrid(np.arange(size[0]), np.arange(size[1])), axis=-1)
        if camera.distortion and any(camera.distortion):
            undistorted = _undistort_pixels(
                grid.reshape(-1, 1, 2).astype(np.float64),
                camera.matrix(),
                camera.distortion_array(),
                (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-6),
            ).reshape(size[1], size[0], 2)
        else:
            undistorted = grid.astype(np.float64)
        overflow = max(
            -undistorted[..., 0].min(),
            -undistorted[..., 1].min(),
            undistorted[..., 0].max() - (size[0] - 1),
            undistorted[..., 1].max() - (size[1] - 1),
            0.0,
        )
        self.margin = int(math.ceil(overflow)) + 2
        self.canvas_size = (size[0] + 2 * self.margin, size[1] + 2 * self.margin)
        self.map_x = (undistorted[..., 0] + self.margin).astype(np.float32)
        self.map_y = (undistorted[..., 1] + self.margin).astype(np.float32)
        noise_rng = np.random.default_rng(seed + 7919)
        self.noise_bank = [
            np.round(
                noise_rng.standard_normal((size[1] + 64, size[0] + 64, 3), dtype=np.float32)
                * noise_sigma
            ).astype(np.int16)
            for _ in range(3)
        ]
        self.canvas_matrix = camera.matrix().copy()
        self.canvas_matrix[0, 2] += self.margin
        self.canvas_matrix[1, 2] += self.margin

    def render_pinhole(self, rotation: np.ndarray, position: np.ndarray) -> np.ndarray:
        """The undistorted view (BGR) on the padded canvas."""
        width, height = self.canvas_size
        canvas = np.zeros((height, width, 3), np.uint8)
        rotation_cw = rotation.T
        extrinsic = np.concatenate([rotation_cw, (-rotation_cw @ position)[:, None]], axis=1)
        for plane in self.room:
            self._draw(canvas, plane, rotation_cw, position, extrinsic)
        order = sorted(
            self.objects,
            key=lambda group: -np.linalg.norm(group[-1].origin - position),
        )
        for group in order:
            for plane in group:
                self._draw(canvas, plane, rotation_cw, position, extrinsic)
        return canvas

    def _draw(
        self,
        canvas: np.ndarray,
        plane: TexturedPlane,
        rotation_cw: np.ndarray,
        position: np.ndarray,
        extrinsic: np.ndarray,
    ) -> None:
        """Warp one plane's texture into the canvas inside its visible (near-clipped) outline."""
        corners_camera = (plane.corners() - position) @ rotation_cw.T
        polygon_camera = _clip_near(corners_camera, NEAR_PLANE_M)
        if len(polygon_camera) < 3:
            return
        projected = polygon_camera @ self.canvas_matrix.T
        polygon = projected[:, :2] / projected[:, 2:3]
        height, width = canvas.shape[:2]
        x0 = max(int(math.floor(polygon[:, 0].min())) - 1, 0)
        y0 = max(int(math.floor(polygon[:, 1].min())) - 1, 0)
        x1 = min(int(math.ceil(polygon[:, 0].max())) + 2, width)
        y1 = min(int(math.ceil(polygon[:, 1].max())) + 2, height)
        if x1 <= x0 or y1 <= y0:
            return
        # Texel -> image homography of level 0, then the mip level for the texel density at the
        # visible polygon's centre.
        projection = self.canvas_matrix @ extrinsic
        affine = plane.texel_to_world(0)
        homography0 = projection @ np.vstack([affine, [0.0, 0.0, 1.0]])
        level = self._mip_level(plane, homography0, polygon.mean(axis=0))
        homography = projection @ np.vstack([plane.texel_to_world(level), [0.0, 0.0, 1.0]])
        shift = np.array([[1.0, 0.0, -x0], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]])
        warped = cv2.warpPerspective(
            plane.mip_levels[level],
            shift @ homography,
            (x1 - x0, y1 - y0),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        )
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        points = np.round((polygon - [x0, y0]) * 16).astype(np.int32)
        region = canvas[y0:y1, x0:x1]
        if plane.smooth_edges:
            cv2.fillPoly(mask, [points], 255, lineType=cv2.LINE_AA, shift=4)
            alpha = mask.astype(np.float32) / 255.0
            region[:] = cv2.blendLinear(warped, region, alpha, 1.0 - alpha)
        else:
            cv2.fillPoly(mask, [points], 255, lineType=cv2.LINE_8, shift=4)
            cv2.copyTo(warped, mask, region)

    @staticmethod
    def _mip_level(plane: TexturedPlane, homography: np.ndarray, image_point: np.ndarray) -> int:
        inverse = np.linalg.inv(homography)
        texel = inverse @ np.array([image_point[0], image_point[1], 1.0])
        texel = texel[:2] / texel[2]
        # Image pixels per texel: sqrt of the Jacobian determinant of texel -> image at `texel`.
        step = 1.0
        points = (
            np.array(
                [
                    [texel[0], texel[1], 1.0],
                    [texel[0] + step, texel[1], 1.0],
                    [texel[0], texel[1] + step, 1.0],
                ]
            )
            @ homography.T
        )
        pixels = points[:, :2] / points[:, 2:3]
        jacobian = np.stack([pixels[1] - pixels[0], pixels[2] - pixels[0]], axis=1)
        density = math.sqrt(abs(np.linalg.det(jacobian))) + 1e-12
        level = int(math.floor(math.log2(1.0 / density))) if density < 1.0 else 0
        return int(np.clip(level, 0, len(plane.mip_levels) - 1))

    def render(
        self,
        rotation: np.ndarray,
        position: np.ndarray,
        *,
        blur_px: tuple[float, float] = (0.0, 0.0),
        gain: float = 1.0,
        gamma: float = 1.0,
        noise_index: int = 0,
        noise_offset: tuple[int, int] = (0, 0),
    ) -> np.ndarray:
        """The camera's frame (BGR uint8): distortion, then a linear motion blur of vector
        `blur_px`, the lighting curve 255 * gain * (I / 255)^gamma, and sensor noise."""
        canvas = self.render_pinhole(rotation, position)
        frame = cv2.remap(canvas, self.map_x, self.map_y, cv2.INTER_LINEAR)
        length = math.hypot(*blur_px)
        if length >= 1.0:
            frame = cv2.filter2D(frame, -1, _line_kernel(blur_px))
        levels = np.arange(256, dtype=np.float64) / 255.0
        lut = np.clip(255.0 * gain * levels**gamma, 0, 255).astype(np.uint8)
        frame = cv2.LUT(frame, lut)
        if self.noise_bank:
            dy, dx = noise_offset
            noise = self.noise_bank[noise_index % len(self.noise_bank)]
            field = noise[dy : dy + frame.shape[0], dx : dx + frame.shape[1]]
            frame = cv2.add(frame, field, dtype=cv2.CV_8U)
        return frame


def _line_kernel(blur_px: tuple[float, float]) -> np.ndarray:
    """Normalised kernel of a line segment of vector `blur_px` (anti-aliased)."""
    length = math.hypot(*blur_px)
    size = int(math.ceil(length)) | 1
    size += 2
    kernel = np.zeros((size, size), np.float32)
    centre = (size - 1) / 2.0
    half = np.array(blur_px) / 2.0
    start = (centre - half[0], centre - half[1])
    stop = (centre + half[0], centre + half[1])
    cv2.line(
        kernel,
        (round(start[0] * 16), round(start[1] * 16)),
        (round(stop[0] * 16), round(stop[1] * 16)),
        1.0,
        1,
        cv2.LINE_AA,
        4,
    )
    return kernel / kernel.sum()


def blur_vector(
    camera: CameraIntrinsics,
    trajectory: Callable[[float], tuple[np.ndarray, np.ndarray]],
    t: float,
    exposure_s: float,
) -> tuple[float, float]:
    """Median image motion of the landmark centres during the exposure (pixels)."""
    points = np.array([placed.centre for placed in LANDMARK_LAYOUT.values()])
    tracks = []
    for moment in (t, t + exposure_s):
        rotation, position = trajectory(moment)
        tracks.append(project_points(camera, points, rotation, position))
    motion = np.median(tracks[1] - tracks[0], axis=0)
    return (float(motion[0]), float(motion[1]))


def render_sequence(
    out_dir: str | Path,
    spec: SequenceSpec,
    progress: Callable[[int], None] | None = None,
) -> Path:
    """Render one sequence into `out_dir` (created): img/00001.jpg..., scene.json, boxes.json,
    poses_gt.tum, groundtruth/<landmark>.txt, sequence.json. Returns the folder.

    `progress` is called with 1 after each frame.
    """
    settings = spec.settings
    out = Path(out_dir)
    camera = default_camera(settings.width, settings.height, settings.distortion)
    scene = default_scene(camera)
    timestamps, rotations, positions = ground_truth_poses(spec)
    boxes = ground_truth_boxes(camera, rotations, positions)
    problems = visibility_problems(
        camera, rotations, positions, margin_px=4.0 * settings.width / 1280
    )
    if problems:
        raise InputError(
            f"trajectory {spec.trajectory!r} with {spec.frames} frames loses a landmark: "
            f"{problems[0]} ({len(problems)} problem(s))"
        )
    _write_ground_truth(out, spec, scene, boxes, (timestamps, rotations, positions))

    renderer = Renderer(camera, spec.seed, settings.noise_sigma)
    conditions = frame_conditions(spec)
    trajectory = spec.camera_path()
    rng = np.random.default_rng(spec.seed + 15485863)
    for index in range(spec.frames):
        blur = blur_vector(
            camera, trajectory, float(timestamps[index]), float(conditions.exposure_s[index])
        )
        frame = renderer.render(
            rotations[index],
            positions[index],
            blur_px=blur,
            gain=float(conditions.gain[index]),
            gamma=float(conditions.gamma[index]),
            noise_index=index,
            noise_offset=(int(rng.integers(0, 64)), int(rng.integers(0, 64))),
        )
        path = out / "img" / f"{index + 1:05d}.jpg"
        write_image(path, frame, [cv2.IMWRITE_JPEG_QUALITY, settings.jpeg_quality])
        if progress is not None:
            progress(1)
    return out


def write_sequence_truth(
    out: Path,
    scene: Scene,
    boxes: Mapping[str, Sequence[Sequence[float]]],
    timestamps: np.ndarray,
    rotations: np.ndarray,
    positions: np.ndarray,
) -> None:
    """scene.json, boxes.json (the first frame's boxes), poses_gt.tum and
    groundtruth/<landmark>.txt (one x,y,w,h row per frame) of a rendered sequence."""
    save_scene(scene, out / "scene.json")
    first_boxes = [
        f"  {json.dumps(k)}: [{', '.join(f'{v:.2f}' for v in b[0])}]" for k, b in boxes.items()
    ]
    write_text(out / "boxes.json", "{\n" + ",\n".join(first_boxes) + "\n}\n")
    write_tum(
        out / "poses_gt.tum",
        timestamps,
        positions,
        Rotation.from_matrix(rotations).as_quat(canonical=True),
    )
    for landmark_id, rows in boxes.items():
        lines = [",".join(f"{v:.2f}" for v in row) for row in rows]
        write_text(out / "groundtruth" / f"{landmark_id}.txt", "\n".join(lines) + "\n")


def _write_ground_truth(
    out: Path,
    spec: SequenceSpec,
    scene: Scene,
    boxes: dict[str, np.ndarray],
    poses: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> None:
    """scene.json, boxes.json, poses_gt.tum, groundtruth/<landmark>.txt and sequence.json."""
    settings = spec.settings
    timestamps, rotations, positions = poses
    (out / "img").mkdir(parents=True, exist_ok=True)
    (out / "groundtruth").mkdir(exist_ok=True)
    # Frames of an earlier, longer rendering would otherwise stay behind.
    for stale in [
        *(out / "img").glob("[0-9][0-9][0-9][0-9][0-9].jpg"),
        *(out / "groundtruth").glob("*.txt"),
    ]:
        stale.unlink()
    write_sequence_truth(out, scene, boxes, timestamps, rotations, positions)
    metadata = {
        "name": spec.name,
        "trajectory": spec.trajectory,
        "frames": spec.frames,
        "fps": settings.fps,
        "seed": spec.seed,
        "width": settings.width,
        "height": settings.height,
        "boxes": "x,y,w,h, 0-based pixels (the top-left pixel's centre is (0, 0))",
        "poses": "TUM, camera-to-world, OpenCV camera axes (x right, y down, z forward)",
    }
    write_text(out / "sequence.json", json.dumps(metadata, indent=2) + "\n")
