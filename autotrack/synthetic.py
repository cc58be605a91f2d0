"""A synthetic test bed like the paper's localisation experiment (section 5.3, Table 3).

An indoor room (wooden floor, painted walls with posters and doors, tiled ceiling) with four
distinct planar landmarks, two on the back wall and two on stands at different depths, filmed by
a camera modelled on the paper's Intel RealSense R200 colour stream (1280x720, 10 fps, ~70 deg
horizontal field of view, mild lens distortion) moving along one of six trajectories. Each frame
carries a global lighting change (gain and gamma drift, a dimming event), sensor noise, motion
blur in long-exposure bursts and JPEG compression; the ground truth (camera poses, intrinsics,
landmark positions, per-frame landmark boxes) is exact.

Rendering uses OpenCV only: every plane is one `cv2.warpPerspective` of a procedurally generated
texture (a mip level chosen per frame) into the bounding rectangle of its visible polygon, drawn
far to near; lens distortion is one `cv2.remap`. Everything is seeded: the same seed gives the
same bytes.

World frame: x right, y forward (towards the back wall), z up, metres. Camera: OpenCV convention.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from autotrack.errors import InputError
from autotrack.localize import project_points, write_tum
from autotrack.scene import CameraIntrinsics, Landmark, Scene, save_scene

TRAJECTORIES = (
    "circle",
    "figure_eight",
    "lateral_sweep",
    "approach_retreat",
    "hover_jitter",
    "climb_yaw",
)
"""The six camera trajectories, in the order of the paper's datasets (a)-(f)."""

PAPER_FRAME_COUNTS = (652, 431, 400, 381, 352, 450)
"""Frames of the paper's six localisation datasets (Table 3; 2,666 in all)."""

ROOM_X = (-3.5, 3.5)
ROOM_Y = (-3.0, 7.0)
ROOM_HEIGHT = 3.0
STAND_BOARD_HALF_M = 0.2
TEXEL_M = 0.005
LANDMARK_TEXELS = 256
NEAR_PLANE_M = 0.05
LOOK_TARGET = np.array([0.05, 5.4, 1.2])


@dataclass(frozen=True)
class PlacedLandmark:
    """Where a test-bed landmark is and what it looks like."""

    centre: tuple[float, float, float]
    """Centre of the square (world metres): the landmark's position in scene.json."""
    pattern: str
    """Texture: rings, checker, star or blocks."""
    mount: str
    """'wall' (on the back wall) or 'stand' (on a board on a pole)."""
    side_m: float
    """Side of the square (metres)."""


# The layout of the paper's figure 6: two landmarks on the back wall, two on stands at
# different depths; deliberately non-coplanar and asymmetric. Squares face -y.
LANDMARK_LAYOUT: dict[str, PlacedLandmark] = {
    "A": PlacedLandmark((-1.4, ROOM_Y[1] - 0.005, 1.9), "rings", "wall", 0.40),
    "B": PlacedLandmark((1.3, ROOM_Y[1] - 0.005, 1.35), "checker", "wall", 0.36),
    "C": PlacedLandmark((-0.45, 4.4, 1.0), "star", "stand", 0.30),
    "D": PlacedLandmark((0.7, 3.4, 0.85), "blocks", "stand", 0.26),
}
LANDMARK_NAMES = {
    "rings": "red and white rings",
    "checker": "blue checkerboard",
    "star": "green Siemens star",
    "blocks": "amber block code",
}


@dataclass(frozen=True)
class RenderSettings:
    """Image formation of the synthetic camera."""

    width: int = 1280
    """Image width (pixels); intrinsics scale with it."""
    height: int = 720
    """Image height (pixels)."""
    fps: float = 10.0
    """Frame rate (frames per second), as in the paper."""
    jpeg_quality: int = 90
    """JPEG quality of the written frames."""
    noise_sigma: float = 2.5
    """Gaussian sensor noise, grey levels (1 sigma)."""
    exposure_s: float = 0.012
    """Normal exposure time (seconds): the motion-blur length follows the motion during it."""
    burst_exposure_s: float = 0.07
    """Exposure during long-exposure bursts (seconds), which blur visibly."""
    burst_fraction: float = 0.12
    """Share of the frames inside long-exposure bursts."""
    gain_amplitude: float = 0.22
    """Amplitude of the slow global gain drift (fraction)."""
    gamma_amplitude: float = 0.15
    """Amplitude of the slow gamma drift."""
    dimming_depth: float = 0.35
    """Depth of the one dimming event per sequence (fraction of the brightness)."""
    distortion: tuple[float, ...] = (-0.045, 0.02, 0.0004, -0.0003, 0.0)
    """Lens distortion (OpenCV k1, k2, p1, p2, k3)."""


@dataclass(frozen=True)
class SequenceSpec:
    """One synthetic sequence."""

    name: str
    """Folder name."""
    trajectory: str
    """One of TRAJECTORIES."""
    frames: int
    """Number of frames."""
    seed: int
    """Seed of textures, trajectory details, lighting, bursts and noise."""
    settings: RenderSettings = RenderSettings()
    period_s: float | None = None
    """Time the trajectory takes to play out (seconds); None: the sequence's duration. A longer
    period renders only the start of the trajectory, at its normal speed."""

    def camera_path(self) -> Callable[[float], tuple[np.ndarray, np.ndarray]]:
        """The camera pose (rotation camera-to-world, position) as a function of time (s)."""
        period = self.period_s or self.frames / self.settings.fps
        return camera_trajectory(self.trajectory, period, self.seed)


# ---------------------------------------------------------------------------------------------
# Camera, scene and trajectories


def default_camera(
    width: int = 1280, height: int = 720, distortion: Sequence[float] = ()
) -> CameraIntrinsics:
    """An R200-like colour camera (fx = fy = 920 px at 1280x720, ~70 deg HFOV), scaled to size."""
    base = CameraIntrinsics(
        fx=920.0,
        fy=920.0,
        cx=641.3,
        cy=357.8,
        distortion=tuple(float(v) for v in distortion),
        width=1280,
        height=720,
    )
    if abs(width / 1280 - height / 720) > 1e-9:
        raise InputError(f"the synthetic camera is 16:9; {width}x{height} is not")
    return base if width == 1280 else base.scaled(width / 1280)


def default_scene(camera: CameraIntrinsics) -> Scene:
    """The test bed's scene: the four landmarks of LANDMARK_LAYOUT seen by `camera`."""
    landmarks = tuple(
        Landmark(
            id=landmark_id, position=np.array(placed.centre), name=LANDMARK_NAMES[placed.pattern]
        )
        for landmark_id, placed in LANDMARK_LAYOUT.items()
    )
    return Scene(
        camera=camera,
        landmarks=landmarks,
        description=(
            "AutoTrack Studio synthetic test bed: landmark positions are the centres of "
            "squares (26-40 cm) facing -y; world x right, y forward, z up."
        ),
    )


def look_at(position: np.ndarray, target: np.ndarray, roll_rad: float = 0.0) -> np.ndarray:
    """Camera-to-world rotation of a camera at `position` looking at `target` (z up, no roll),
    then rolled about its optical axis."""
    forward = target - position
    forward = forward / np.linalg.norm(forward)
    right = np.cross(forward, np.array([0.0, 0.0, 1.0]))
    right = right / np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.stack([right, down, forward], axis=1)
    if roll_rad:
        c, s = math.cos(roll_rad), math.sin(roll_rad)
        rotation = rotation @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rotation


def _yaw_pitch(rotation: np.ndarray, yaw_rad: float, pitch_rad: float) -> np.ndarray:
    """Turn a camera about the world vertical (yaw) and its own x axis (pitch)."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    c, s = math.cos(pitch_rad), math.sin(pitch_rad)
    pitch = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return yaw @ rotation @ pitch


class _Vibration:
    """Smooth pseudo-random wobble: a sum of sines with seeded frequencies and phases."""

    def __init__(
        self, rng: np.random.Generator, amplitude: float, frequencies_hz: tuple[float, float]
    ):
        self.amplitude = amplitude
        self.frequencies = rng.uniform(*frequencies_hz, size=(3, 3))
        self.phases = rng.uniform(0.0, 2.0 * math.pi, size=(3, 3))

    def __call__(self, t: float) -> np.ndarray:
        waves = np.sin(2.0 * math.pi * self.frequencies * t + self.phases)
        return self.amplitude * waves.sum(axis=1) / 3.0


def camera_trajectory(
    name: str, duration_s: float, seed: int
) -> Callable[[float], tuple[np.ndarray, np.ndarray]]:
    """Continuous camera pose t -> (rotation camera-to-world, position) for t in [0, duration_s].

    Every trajectory keeps the four landmarks in view and adds a UAV-like wobble (about 1 cm,
    0.4 deg); `hover_jitter` is mostly wobble.
    """
    if name not in TRAJECTORIES:
        raise InputError(f"unknown trajectory {name!r} (choose from {', '.join(TRAJECTORIES)})")
    rng = np.random.default_rng(seed)
    shake = _Vibration(rng, 0.012, (0.4, 2.5))
    tilt = _Vibration(rng, math.radians(0.5), (0.5, 3.0))
    drift = _Vibration(rng, 0.10, (0.02, 0.08))
    two_pi = 2.0 * math.pi
    period = duration_s

    def pose(t: float) -> tuple[np.ndarray, np.ndarray]:
        phase = two_pi * t / period
        yaw = pitch = roll = 0.0
        target = LOOK_TARGET.copy()
        if name == "circle":
            position = np.array(
                [0.8 * math.sin(1.5 * phase), 1.3 - 0.45 * math.cos(1.5 * phase), 1.35]
            )
            position[2] += 0.12 * math.sin(3.0 * phase)
        elif name == "figure_eight":
            position = np.array(
                [0.85 * math.sin(2 * phase), 1.4, 1.42 + 0.28 * math.sin(4 * phase)]
            )
        elif name == "lateral_sweep":
            position = np.array([1.1 * math.sin(1.5 * phase), 1.2, 1.45])
            # The heading follows only part of the sideways motion: the view sweeps too.
            target[0] += 0.45 * position[0]
        elif name == "approach_retreat":
            position = np.array(
                [
                    0.25 * math.sin(phase),
                    1.15 - 0.7 * math.cos(2 * phase),
                    1.3 + 0.1 * math.sin(phase),
                ]
            )
        elif name == "hover_jitter":
            # A hovering UAV: slow drift and twice the usual wobble.
            position = np.array([0.1, 1.2, 1.3]) + drift(t) + shake(t)
            yaw, pitch = 1.0 * tilt(t)[0], 1.0 * tilt(t)[1]
        else:  # climb_yaw
            position = np.array(
                [-0.2 + 0.3 * math.sin(phase), 1.25, 1.5 - 0.38 * math.cos(2 * phase)]
            )
            yaw = math.radians(9.0) * math.sin(3 * phase)
        position = position + shake(t)
        wobble = tilt(t)
        rotation = look_at(position, target, roll_rad=roll + wobble[2])
        rotation = _yaw_pitch(rotation, yaw + wobble[0], pitch + wobble[1])
        return rotation, position

    return pose


def ground_truth_poses(spec: SequenceSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Timestamps (n,), camera-to-world rotations (n, 3, 3) and positions (n, 3) of a sequence."""
    fps = spec.settings.fps
    trajectory = spec.camera_path()
    timestamps = np.arange(spec.frames) / fps
    poses = [trajectory(float(t)) for t in timestamps]
    rotations = np.stack([r for r, _ in poses])
    positions = np.stack([p for _, p in poses])
    return timestamps, rotations, positions


def landmark_corners(landmark_id: str) -> np.ndarray:
    """World corners (4, 3) of a landmark square: top-left, top-right, bottom-right, bottom-left
    as seen from the camera (the squares face -y)."""
    placed = LANDMARK_LAYOUT[landmark_id]
    centre = np.array(placed.centre)
    half = placed.side_m / 2.0
    right = np.array([1.0, 0.0, 0.0])
    down = np.array([0.0, 0.0, -1.0])
    return np.stack(
        [
            centre - half * right - half * down,
            centre + half * right - half * down,
            centre + half * right + half * down,
            centre - half * right + half * down,
        ]
    )


def landmark_box(
    camera: CameraIntrinsics, landmark_id: str, rotation: np.ndarray, position: np.ndarray
) -> tuple[float, float, float, float]:
    """Bounding box (x, y, w, h, 0-based pixels) of a landmark square's projection, distortion
    included (edges sampled densely, as distortion bends them)."""
    corners = landmark_corners(landmark_id)
    steps = np.linspace(0.0, 1.0, 9)[:-1, None]
    outline = np.concatenate(
        [corners[k] + steps * (corners[(k + 1) % 4] - corners[k]) for k in range(4)]
    )
    projected = project_points(camera, outline, rotation, position)
    u, v = projected[:, 0], projected[:, 1]
    x0, y0 = float(u.min()), float(v.min())
    return (x0, y0, float(u.max()) - x0, float(v.max()) - y0)


def ground_truth_boxes(
    camera: CameraIntrinsics, rotations: np.ndarray, positions: np.ndarray
) -> dict[str, np.ndarray]:
    """Per landmark, the (n, 4) per-frame boxes (x, y, w, h, 0-based pixels)."""
    return {
        landmark_id: np.array(
            [
                landmark_box(camera, landmark_id, r, p)
                for r, p in zip(rotations, positions, strict=True)
            ]
        )
        for landmark_id in LANDMARK_LAYOUT
    }


def stand_corners(landmark_id: str) -> list[np.ndarray]:
    """World outlines of the stand carrying a landmark (board, pole); empty for wall landmarks."""
    placed = LANDMARK_LAYOUT[landmark_id]
    cx, cy, cz = placed.centre
    if placed.mount != "stand":
        return []
    half = STAND_BOARD_HALF_M
    board_y = cy + 0.01
    board = np.array(
        [
            [cx - half, board_y, cz + half],
            [cx + half, board_y, cz + half],
            [cx + half, board_y, cz - half],
            [cx - half, board_y, cz - half],
        ]
    )
    pole = np.array(
        [
            [cx - 0.025, board_y + 0.02, cz - half],
            [cx + 0.025, board_y + 0.02, cz - half],
            [cx + 0.025, board_y + 0.02, 0.0],
            [cx - 0.025, board_y + 0.02, 0.0],
        ]
    )
    return [board, pole]


def _projected_bounds(
    camera: CameraIntrinsics, points: np.ndarray, rotation: np.ndarray, position: np.ndarray
) -> tuple[float, float, float, float]:
    """(u0, v0, u1, v1) bounds of the projected points (corners only: fine for occlusion tests)."""
    projected = project_points(camera, points, rotation, position)
    u, v = projected[:, 0], projected[:, 1]
    return float(u.min()), float(v.min()), float(u.max()), float(v.max())


def visibility_problems(
    camera: CameraIntrinsics, rotations: np.ndarray, positions: np.ndarray, margin_px: float
) -> list[str]:
    """Frames where a landmark is not fully and cleanly visible: closer than `margin_px` to the
    image border, less than 0.5 m in front of the camera, or possibly hidden by a nearer stand."""
    problems = []
    for frame, (rotation, position) in enumerate(zip(rotations, positions, strict=True)):
        depths = {
            landmark_id: float((np.array(placed.centre) - position) @ rotation[:, 2])
            for landmark_id, placed in LANDMARK_LAYOUT.items()
        }
        if min(depths.values()) < 0.5:
            problems.append(f"frame {frame}: a landmark is less than 0.5 m in front of the camera")
            continue
        for landmark_id in LANDMARK_LAYOUT:
            x, y, w, h = landmark_box(camera, landmark_id, rotation, position)
            if (
                x < margin_px
                or y < margin_px
                or x + w > camera.width - margin_px
                or (y + h > camera.height - margin_px)
            ):
                problems.append(f"frame {frame}: landmark {landmark_id} near the border")
            for other in LANDMARK_LAYOUT:
                if other == landmark_id or depths[other] >= depths[landmark_id]:
                    continue
                for outline in [landmark_corners(other), *stand_corners(other)]:
                    u0, v0, u1, v1 = _projected_bounds(camera, outline, rotation, position)
                    if u0 < x + w and x < u1 and v0 < y + h and y < v1:
                        problems.append(f"frame {frame}: landmark {landmark_id} hidden by {other}")
                        break
    return problems


# ---------------------------------------------------------------------------------------------
# Procedural textures (BGR uint8)


def _smooth_noise(
    rng: np.random.Generator, height: int, width: int, cell_texels: float, octaves: int = 3
) -> np.ndarray:
    """Fractal value noise in about [-1, 1], float32, features of `cell_texels` and finer."""
    out = np.zeros((height, width), np.float32)
    total = 0.0
    for octave in range(octaves):
        cell = max(cell_texels / 2**octave, 2.0)
        small = rng.standard_normal(
            (max(int(height / cell) + 2, 2), max(int(width / cell) + 2, 2))
        ).astype(np.float32)
        out += cv2.resize(small, (width, height), interpolation=cv2.INTER_CUBIC) * 0.5**octave
        total += 0.5**octave
    return out / total


def _shade(base_bgr: Sequence[float], variation: np.ndarray, strength: float) -> np.ndarray:
    base = np.asarray(base_bgr, np.float32)[None, None, :]
    return np.clip(base * (1.0 + strength * variation[:, :, None]), 0, 255)


def floor_texture(rng: np.random.Generator, width_m: float, length_m: float) -> np.ndarray:
    """Wooden planks running along y (texture rows = y from the far end, columns = x)."""
    width, height = round(width_m / TEXEL_M), round(length_m / TEXEL_M)
    plank = round(0.14 / TEXEL_M)
    grain = cv2.resize(
        rng.standard_normal((height // 40 + 2, width // 2 + 2)).astype(np.float32),
        (width, height),
        interpolation=cv2.INTER_CUBIC,
    )
    image = np.empty((height, width, 3), np.float32)
    browns = np.array([[60, 105, 150], [50, 90, 135], [70, 120, 165], [45, 80, 120]], np.float32)
    for start in range(0, width, plank):
        stop = min(start + plank, width)
        colour = browns[rng.integers(len(browns))] * rng.uniform(0.9, 1.1)
        image[:, start:stop] = colour
        image[:, start : start + 2] *= 0.45  # gap between planks
        joint = int(rng.integers(0, height))
        for row in range(joint % round(1.2 / TEXEL_M), height, round(1.2 / TEXEL_M)):
            image[row : row + 2, start:stop] *= 0.5  # plank ends, staggered
    image *= (1.0 + 0.12 * grain)[:, :, None]
    image *= (1.0 + 0.08 * _smooth_noise(rng, height, width, 120))[:, :, None]
    return np.clip(image, 0, 255).astype(np.uint8)


def _poster(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    kind = rng.integers(4)
    colours = rng.uniform(30, 230, size=(4, 3)).astype(np.float32)
    poster = np.empty((height, width, 3), np.float32)
    poster[:] = colours[0]
    if kind == 0:  # stripes
        stripe = max(width // int(rng.integers(4, 9)), 2)
        for x in range(0, width, 2 * stripe):
            poster[:, x : x + stripe] = colours[1]
    elif kind == 1:  # text-like lines under a title block
        poster[: height // 4] = colours[1]
        for y in range(height // 3, height - 8, 14):
            length = int(rng.integers(width // 3, width - 10))
            poster[y : y + 5, 8 : 8 + length] = colours[2] * 0.3
    elif kind == 2:  # colour blocks
        for _ in range(6):
            x0, y0 = int(rng.integers(0, width - 4)), int(rng.integers(0, height - 4))
            x1, y1 = x0 + int(rng.integers(8, width // 2)), y0 + int(rng.integers(8, height // 2))
            poster[y0:y1, x0:x1] = colours[int(rng.integers(1, 4))]
    else:  # a landscape-like gradient with a disc
        ramp = np.linspace(0.0, 1.0, height, dtype=np.float32)[:, None, None]
        poster[:] = colours[1] * (1 - ramp) + colours[2] * ramp
        centre = (
            int(rng.integers(width // 4, 3 * width // 4)),
            int(rng.integers(height // 5, height // 2)),
        )
        cv2.circle(poster, centre, max(min(width, height) // 6, 3), colours[3].tolist(), -1)
    cv2.rectangle(poster, (0, 0), (width - 1, height - 1), (245, 245, 245), 4)
    return poster


def wall_texture(
    rng: np.random.Generator,
    width_m: float,
    height_m: float,
    keep_clear: Sequence[tuple[float, float, float, float]] = (),
) -> np.ndarray:
    """Painted wall with a skirting board, a door and posters (texture columns = along the wall,
    rows = down from the ceiling). `keep_clear` lists (u0, v0, u1, v1) metre rectangles (u along,
    v down) where no poster goes (behind landmarks)."""
    width, height = round(width_m / TEXEL_M), round(height_m / TEXEL_M)
    paints = [(200, 215, 225), (190, 205, 200), (215, 210, 200), (205, 195, 185)]
    image = _shade(
        paints[int(rng.integers(len(paints)))], _smooth_noise(rng, height, width, 200), 0.05
    )
    skirting = round(0.10 / TEXEL_M)
    image[height - skirting :] = (70, 75, 80)
    door_width, door_height = round(0.9 / TEXEL_M), round(2.05 / TEXEL_M)
    door_x = int(rng.integers(round(0.3 / TEXEL_M), width - door_width - round(0.3 / TEXEL_M)))
    door_u = (door_x * TEXEL_M, (door_x + door_width) * TEXEL_M)
    clear = [*keep_clear]
    if not any(
        u0 < door_u[1] and door_u[0] < u1 and v1 > height_m - 2.05 for u0, _, u1, v1 in clear
    ):
        image[height - door_height : height, door_x : door_x + door_width] = (40, 70, 110)
        cv2.rectangle(
            image, (door_x, height - door_height), (door_x + door_width, height), (30, 50, 80), 8
        )
        cv2.circle(
            image, (door_x + door_width - 40, height - door_height // 2), 10, (180, 180, 180), -1
        )
        clear.append((door_u[0], height_m - 2.05, door_u[1], height_m))
    for _ in range(40):
        if len(clear) > 12:
            break
        w_m, h_m = rng.uniform(0.4, 1.1), rng.uniform(0.4, 0.9)
        u0, v0 = rng.uniform(0.1, width_m - w_m - 0.1), rng.uniform(0.3, height_m - h_m - 0.5)
        if any(
            u0 < b[2] + 0.15
            and b[0] - 0.15 < u0 + w_m
            and v0 < b[3] + 0.15
            and b[1] - 0.15 < v0 + h_m
            for b in clear
        ):
            continue
        x0, y0 = round(u0 / TEXEL_M), round(v0 / TEXEL_M)
        pw, ph = round(w_m / TEXEL_M), round(h_m / TEXEL_M)
        image[y0 : y0 + ph, x0 : x0 + pw] = _poster(rng, ph, pw)
        clear.append((u0, v0, u0 + w_m, v0 + h_m))
    return np.clip(image, 0, 255).astype(np.uint8)


def ceiling_texture(rng: np.random.Generator, width_m: float, length_m: float) -> np.ndarray:
    """Suspended ceiling: 0.6 m tiles, some of them light panels."""
    width, height = round(width_m / (2 * TEXEL_M)), round(length_m / (2 * TEXEL_M))
    image = _shade((215, 218, 220), _smooth_noise(rng, height, width, 60), 0.04)
    tile = round(0.6 / (2 * TEXEL_M))
    for x in range(0, width, tile):
        for y in range(0, height, tile):
            if rng.random() < 0.15:
                image[y + 3 : y + tile - 3, x + 3 : x + tile - 3] = (250, 252, 252)
    image[:, ::tile] = (150, 150, 150)
    image[::tile, :] = (150, 150, 150)
    return np.clip(image, 0, 255).astype(np.uint8)


def landmark_texture(pattern: str, rng: np.random.Generator) -> np.ndarray:
    """A distinct high-contrast 256x256 pattern with a white margin and a black outline."""
    n = LANDMARK_TEXELS
    image = np.full((n, n, 3), 255, np.uint8)
    inner = slice(16, n - 16)
    if pattern == "rings":
        yy, xx = np.mgrid[0:n, 0:n]
        radius = np.hypot(xx - (n - 1) / 2, yy - (n - 1) / 2)
        red = (np.floor(radius / 18) % 2 == 0) & (radius < 112)
        image[red] = (30, 30, 210)
    elif pattern == "checker":
        yy, xx = np.mgrid[0:n, 0:n]
        cells = ((yy - 16) // 45 + (xx - 16) // 45) % 2 == 0
        block = np.zeros((n, n), bool)
        block[inner, inner] = True
        image[cells & block] = (170, 60, 20)
    elif pattern == "star":
        yy, xx = np.mgrid[0:n, 0:n]
        angle = np.arctan2(yy - (n - 1) / 2, xx - (n - 1) / 2)
        radius = np.hypot(xx - (n - 1) / 2, yy - (n - 1) / 2)
        dark = (np.floor(angle / (2 * math.pi / 16)) % 2 == 0) & (radius < 112)
        image[dark] = (20, 20, 20)
        image[(~dark) & (radius < 112)] = (60, 190, 60)
    elif pattern == "blocks":
        code = rng.random((6, 6)) < 0.5
        code[0, 0] = code[5, 5] = True
        code[0, 5] = code[5, 0] = False
        cells = cv2.resize(code.astype(np.uint8), (n - 32, n - 32), interpolation=cv2.INTER_NEAREST)
        patch = np.where(cells[:, :, None] > 0, np.array([20, 170, 240], np.uint8), np.uint8(20))
        image[inner, inner] = patch
    else:
        raise InputError(f"unknown landmark pattern {pattern!r}")
    cv2.rectangle(image, (2, 2), (n - 3, n - 3), (0, 0, 0), 5)
    return image


# ---------------------------------------------------------------------------------------------
# Planes and the renderer


@dataclass(frozen=True)
class TexturedPlane:
    """A textured rectangle: texel (i, j) centre = origin + (j + 0.5) du + (i + 0.5) dv."""

    name: str
    origin: np.ndarray
    """World position of the texture's top-left corner (metres)."""
    u_axis: np.ndarray
    """World vector spanned by the texture's full width (metres)."""
    v_axis: np.ndarray
    """World vector spanned by the texture's full height (metres)."""
    mip_levels: tuple[np.ndarray, ...]
    """The texture (BGR uint8) and its successive pyrDown halvings."""
    smooth_edges: bool
    """Anti-aliased outline (objects) or hard outline (room surfaces, which tile the view)."""

    def corners(self) -> np.ndarray:
        """World corners (4, 3) in outline order."""
        o, u, v = self.origin, self.u_axis, self.v_axis
        return np.stack([o, o + u, o + u + v, o + v])

    def texel_to_world(self, level: int) -> np.ndarray:
        """3x3 A with world point = A @ (column j, row i, 1) for texels of mip `level`."""
        texture = self.mip_levels[level]
        height, width = texture.shape[:2]
        du = self.u_axis / width
        dv = self.v_axis / height
        return np.stack([du, dv, self.origin + 0.5 * du + 0.5 * dv], axis=1)


def make_plane(
    name: str, origin, u_axis, v_axis, texture: np.ndarray, smooth_edges: bool
) -> TexturedPlane:
    """A plane with its mip pyramid (down to ~16 texels)."""
    levels = [texture]
    while min(levels[-1].shape[:2]) > 32:
        levels.append(cv2.pyrDown(levels[-1]))
    return TexturedPlane(
        name=name,
        origin=np.asarray(origin, np.float64),
        u_axis=np.asarray(u_axis, np.float64),
        v_axis=np.asarray(v_axis, np.float64),
        mip_levels=tuple(levels),
        smooth_edges=smooth_edges,
    )


def build_world(seed: int) -> tuple[list[TexturedPlane], list[list[TexturedPlane]]]:
    """The room's planes (drawn first, in any order) and the objects (stands with their
    landmarks, wall landmarks), each a list of planes drawn back to front as one group."""
    rng = np.random.default_rng(seed)
    x0, x1 = ROOM_X
    y0, y1 = ROOM_Y
    width_x, length_y, height = x1 - x0, y1 - y0, ROOM_HEIGHT
    back_clear = []
    for placed in LANDMARK_LAYOUT.values():
        if placed.mount == "wall":
            u, v = placed.centre[0] - x0, height - placed.centre[2]
            back_clear.append((u - 0.35, v - 0.35, u + 0.35, v + 0.35))
    room = [
        make_plane(
            "floor",
            (x0, y1, 0.0),
            (width_x, 0, 0),
            (0, -length_y, 0),
            floor_texture(rng, width_x, length_y),
            False,
        ),
        make_plane(
            "ceiling",
            (x0, y0, height),
            (width_x, 0, 0),
            (0, length_y, 0),
            ceiling_texture(rng, width_x, length_y),
            False,
        ),
        make_plane(
            "back wall",
            (x0, y1, height),
            (width_x, 0, 0),
            (0, 0, -height),
            wall_texture(rng, width_x, height, back_clear),
            False,
        ),
        make_plane(
            "left wall",
            (x0, y0, height),
            (0, length_y, 0),
            (0, 0, -height),
            wall_texture(rng, length_y, height),
            False,
        ),
        make_plane(
            "right wall",
            (x1, y1, height),
            (0, -length_y, 0),
            (0, 0, -height),
            wall_texture(rng, length_y, height),
            False,
        ),
        make_plane(
            "rear wall",
            (x1, y0, height),
            (-width_x, 0, 0),
            (0, 0, -height),
            wall_texture(rng, width_x, height),
            False,
        ),
    ]
    objects: list[list[TexturedPlane]] = []
    for landmark_id, placed in LANDMARK_LAYOUT.items():
        centre, side = placed.centre, placed.side_m
        half = side / 2
        cx, cy, cz = centre
        marker = make_plane(
            f"landmark {landmark_id}",
            (cx - half, cy, cz + half),
            (side, 0, 0),
            (0, 0, -side),
            landmark_texture(placed.pattern, rng),
            True,
        )
        if placed.mount == "wall":
            objects.append([marker])
            continue
        board_half = STAND_BOARD_HALF_M
        board_y = cy + 0.01
        board = _shade((150, 150, 145), _smooth_noise(rng, 108, 108, 30), 0.08).astype(np.uint8)
        pole = np.full((64, 8, 3), (55, 55, 60), np.uint8)
        objects.append(
            [
                make_plane(
                    f"pole {landmark_id}",
                    (cx - 0.025, board_y + 0.02, cz - board_half),
                    (0.05, 0, 0),
                    (0, 0, -(cz - board_half)),
                    pole,
                    True,
                ),
                make_plane(
                    f"board {landmark_id}",
                    (cx - board_half, board_y, cz + board_half),
                    (2 * board_half, 0, 0),
                    (0, 0, -2 * board_half),
                    board,
                    True,
                ),
                marker,
            ]
        )
    return room, objects


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


# ---------------------------------------------------------------------------------------------
# Sequences


@dataclass(frozen=True)
class FrameConditions:
    """Per-frame image formation of a sequence."""

    gain: np.ndarray
    gamma: np.ndarray
    exposure_s: np.ndarray


def frame_conditions(spec: SequenceSpec) -> FrameConditions:
    """Lighting drift, one dimming event and the long-exposure bursts of a sequence."""
    settings = spec.settings
    rng = np.random.default_rng(spec.seed + 104729)
    t = np.arange(spec.frames) / settings.fps
    duration = max(spec.period_s or spec.frames / settings.fps, 1.0)
    phases = rng.uniform(0, 2 * math.pi, size=2)
    gain = 1.0 + settings.gain_amplitude * np.sin(2 * math.pi * t / (0.7 * duration) + phases[0])
    dim_at = rng.uniform(0.25, 0.75) * duration
    gain *= 1.0 - settings.dimming_depth * np.exp(-0.5 * ((t - dim_at) / 1.5) ** 2)
    gamma = 1.0 + settings.gamma_amplitude * np.sin(2 * math.pi * t / (0.45 * duration) + phases[1])
    exposure = np.full(spec.frames, settings.exposure_s)
    burst_frames = int(round(settings.burst_fraction * spec.frames))
    while burst_frames > 0:
        length = min(int(rng.integers(8, 20)), burst_frames)
        start = int(rng.integers(1, max(spec.frames - length, 2)))
        exposure[start : start + length] = settings.burst_exposure_s
        burst_frames -= length
    return FrameConditions(gain=gain, gamma=gamma, exposure_s=exposure)


def _blur_vector(
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
    (out / "img").mkdir(parents=True, exist_ok=True)
    (out / "groundtruth").mkdir(exist_ok=True)
    # Frames of an earlier, longer rendering would otherwise stay behind.
    for stale in [
        *(out / "img").glob("[0-9][0-9][0-9][0-9][0-9].jpg"),
        *(out / "groundtruth").glob("*.txt"),
    ]:
        stale.unlink()
    save_scene(scene, out / "scene.json")
    first_boxes = [
        f"  {json.dumps(k)}: [{', '.join(f'{v:.2f}' for v in b[0])}]" for k, b in boxes.items()
    ]
    (out / "boxes.json").write_text("{\n" + ",\n".join(first_boxes) + "\n}\n", encoding="utf-8")
    write_tum(
        out / "poses_gt.tum",
        timestamps,
        positions,
        Rotation.from_matrix(rotations).as_quat(canonical=True),
    )
    for landmark_id, rows in boxes.items():
        lines = [",".join(f"{v:.2f}" for v in row) for row in rows]
        (out / "groundtruth" / f"{landmark_id}.txt").write_text("\n".join(lines) + "\n")
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
    (out / "sequence.json").write_text(json.dumps(metadata, indent=2) + "\n", encoding="utf-8")

    renderer = Renderer(camera, spec.seed, settings.noise_sigma)
    conditions = frame_conditions(spec)
    trajectory = spec.camera_path()
    rng = np.random.default_rng(spec.seed + 15485863)
    for index in range(spec.frames):
        blur = _blur_vector(
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
        if not cv2.imwrite(str(path), frame, [cv2.IMWRITE_JPEG_QUALITY, settings.jpeg_quality]):
            raise InputError(f"cannot write {path}")
        if progress is not None:
            progress(1)
    return out


def sequence_specs(
    sequences: int = 6,
    frames: int | None = None,
    seed: int = 0,
    settings: RenderSettings | None = None,
) -> list[SequenceSpec]:
    """The test bed: sequence k uses trajectory k (cycling) and the paper's k-th frame count
    unless `frames` is given."""
    if sequences < 1:
        raise InputError("generate at least one sequence")
    if frames is not None and frames < 2:
        raise InputError("a sequence needs at least 2 frames")
    settings = settings or RenderSettings()
    specs = []
    for k in range(sequences):
        trajectory = TRAJECTORIES[k % len(TRAJECTORIES)]
        count = frames if frames is not None else PAPER_FRAME_COUNTS[k % len(PAPER_FRAME_COUNTS)]
        name = f"{chr(ord('a') + k % 26)}_{trajectory}"
        specs.append(SequenceSpec(name, trajectory, count, seed * 1000 + k, settings))
    return specs


def generate_test_bed(
    out_dir: str | Path,
    specs: Sequence[SequenceSpec],
    progress: Callable[[int], None] | None = None,
) -> list[Path]:
    """Render every sequence into out_dir/<name>/ and write out_dir/README.md."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    folders = [render_sequence(out / spec.name, spec, progress) for spec in specs]
    lines = [
        "# Synthetic localisation test bed",
        "",
        "Generated by `autotrack synth` (autotrack/synthetic.py); regenerate rather than edit.",
        "",
        "| sequence | trajectory | frames | seed | size |",
        "|---|---|---|---|---|",
    ]
    for spec in specs:
        s = spec.settings
        lines.append(
            f"| {spec.name} | {spec.trajectory} | {spec.frames} | {spec.seed} | {s.width}x{s.height} |"
        )
    (out / "README.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return folders


def read_ground_truth_boxes(folder: str | Path) -> dict[str, np.ndarray]:
    """groundtruth/<landmark>.txt of a generated sequence: landmark id -> (n, 4) boxes."""
    out = {}
    for path in sorted((Path(folder) / "groundtruth").glob("*.txt")):
        out[path.stem] = np.loadtxt(path, delimiter=",", ndmin=2)
    if not out:
        raise InputError(f"no groundtruth/<landmark>.txt files in {folder}")
    return out


DEMO_README = """# Embedded demo

The app's default content: {frames} frames ({width}x{height}, {fps:g} fps) of the synthetic
localisation test bed, trajectory `{trajectory}` (the first {seconds:.1f} s of a {period:g} s
loop), seed {seed}. Generated by `autotrack/synthetic.py`; do not edit by hand, regenerate with

    autotrack synth static/demo --demo

- `img/00001.jpg`... the frames;
- `scene.json` camera intrinsics (with distortion) and the four landmarks (metres);
- `boxes.json` frame-1 box per landmark, `[x, y, w, h]`, 0-based pixels;
- `poses_gt.tum` ground-truth camera poses (TUM: `timestamp tx ty tz qx qy qz qw`,
  camera-to-world);
- `groundtruth/<landmark>.txt` per-frame ground-truth boxes (`x,y,w,h`, 0-based);
- `sequence.json` how it was rendered.

Try it: `autotrack localize static/demo --gt static/demo/poses_gt.tum`.
"""


def demo_spec(seed: int = 0) -> SequenceSpec:
    """The embedded demo: 60 frames at 960x540, the start of a slow circle; JPEG quality 60 and
    light noise keep the folder under 3 MB."""
    settings = RenderSettings(width=960, height=540, jpeg_quality=60, noise_sigma=1.0)
    return SequenceSpec("demo", "circle", 60, seed, settings, period_s=45.0)


def generate_demo(out_dir: str | Path, seed: int = 0) -> SequenceSpec:
    """Render the demo straight into `out_dir` with its README.md; returns its spec."""
    spec = demo_spec(seed)
    render_sequence(out_dir, spec)
    s = spec.settings
    text = DEMO_README.format(
        frames=spec.frames,
        width=s.width,
        height=s.height,
        fps=s.fps,
        trajectory=spec.trajectory,
        seconds=spec.frames / s.fps,
        period=spec.period_s,
        seed=seed,
    )
    (Path(out_dir) / "README.md").write_text(text, encoding="utf-8")
    return spec
