"""What a synthetic sequence is (`SequenceSpec`, `RenderSettings`) and what changes along it: the
six camera trajectories, the ground-truth poses and boxes, the lighting and exposure per frame."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from autotrack.errors import InputError
from autotrack.localization.camera import CameraIntrinsics
from autotrack.synthetic.world import LANDMARK_LAYOUT, LOOK_TARGET, landmark_box

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


def yaw_pitch(rotation: np.ndarray, yaw_rad: float, pitch_rad: float) -> np.ndarray:
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
        rotation = yaw_pitch(rotation, yaw + wobble[0], pitch + wobble[1])
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
