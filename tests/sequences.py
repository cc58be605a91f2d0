"""Sequences the tests generate: a textured target moving and scaling over clutter."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class GeneratedSequence:
    frames: list[np.ndarray]
    """RGB uint8 frames."""
    boxes: np.ndarray
    """(N, 4) ground-truth boxes, 0-based x, y, w, h."""
    angles: np.ndarray | None = None
    """(N,) in-plane angle of the target, degrees counter-clockwise, where one is generated."""


def _clutter(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    noise = rng.uniform(0, 255, size=(height // 8, width // 8, 3)).astype(np.float32)
    coarse = cv2.resize(noise, (width, height), interpolation=cv2.INTER_CUBIC)
    fine = rng.normal(0, 12, size=(height, width, 3)).astype(np.float32)
    return np.clip(0.6 * coarse + 40 + fine, 0, 255)


def _target_texture(rng: np.random.Generator, size: int) -> np.ndarray:
    texture = np.zeros((size, size, 3), dtype=np.float32)
    texture[:] = (200, 40, 40)
    for _ in range(14):
        centre = tuple(int(v) for v in rng.integers(0, size, size=2))
        radius = int(rng.integers(size // 10, size // 4))
        colour = tuple(float(v) for v in rng.integers(0, 255, size=3))
        cv2.circle(texture, centre, radius, colour, thickness=-1)
    cv2.rectangle(texture, (0, 0), (size - 1, size - 1), (250, 250, 30), thickness=3)
    return texture


def moving_target_sequence(
    num_frames: int = 60,
    size_hw: tuple[int, int] = (240, 320),
    target_size: int = 40,
    final_scale: float = 1.3,
    occlusion: tuple[int, int] | None = None,
    seed: int = 7,
    final_aspect: float = 1.0,
) -> GeneratedSequence:
    """A target moving on a smooth path and growing to `final_scale` over static clutter.

    With `final_aspect` != 1 the target's width / height ratio moves steadily to it at constant
    area (a stretching target: width * sqrt(aspect), height / sqrt(aspect)).

    With `occlusion=(first, last)`, those frames show a flat grey block over the whole search
    region around the target (a full occlusion).
    """
    rng = np.random.default_rng(seed)
    height, width = size_hw
    background = _clutter(rng, height, width)
    texture = _target_texture(rng, 64)
    frames, boxes = [], []
    for index in range(num_frames):
        phase = index / max(num_frames - 1, 1)
        scale = 1.0 + (final_scale - 1.0) * phase
        side = target_size * scale
        stretch = final_aspect ** (0.5 * phase)
        side_w, side_h = side * stretch, side / stretch
        cx = width * 0.3 + width * 0.4 * phase + 12 * np.sin(4 * np.pi * phase)
        cy = height * 0.5 + height * 0.15 * np.sin(2 * np.pi * phase)
        zoom_w, zoom_h = side_w / texture.shape[1], side_h / texture.shape[0]
        warp = np.array(
            [
                [zoom_w, 0, cx - side_w / 2 - 0.5 + zoom_w / 2],
                [0, zoom_h, cy - side_h / 2 - 0.5 + zoom_h / 2],
            ],
            dtype=np.float64,
        )
        layer = cv2.warpAffine(texture, warp, (width, height), flags=cv2.INTER_LINEAR)
        mask = cv2.warpAffine(
            np.ones(texture.shape[:2], np.float32), warp, (width, height), flags=cv2.INTER_LINEAR
        )[:, :, None]
        frame = background * (1 - mask) + layer * mask
        if occlusion is not None and occlusion[0] <= index <= occlusion[1]:
            half = int(side * 3)
            top, left = int(cy) - half, int(cx) - half
            frame[max(top, 0) : top + 2 * half, max(left, 0) : left + 2 * half] = 128.0
        frames.append(np.clip(frame, 0, 255).astype(np.uint8))
        boxes.append((cx - side_w / 2, cy - side_h / 2, side_w, side_h))
    return GeneratedSequence(frames=frames, boxes=np.array(boxes))


def accelerating_target_sequence(
    num_frames: int = 24,
    size_hw: tuple[int, int] = (200, 1280),
    target_size: int = 32,
    final_speed: float = 90.0,
    seed: int = 11,
) -> GeneratedSequence:
    """A target crossing the frame left to right, its speed rising steadily from 0 to
    `final_speed` pixels per frame (fast motion that a constant-velocity prediction follows)."""
    rng = np.random.default_rng(seed)
    height, width = size_hw
    background = _clutter(rng, height, width)
    texture = _target_texture(rng, target_size)
    frames, boxes = [], []
    x, cy = 40.0, height / 2.0
    for index in range(num_frames):
        x += final_speed * index / max(num_frames - 1, 1)
        frame = background.copy()
        left, top = int(round(x - target_size / 2)), int(round(cy - target_size / 2))
        frame[top : top + target_size, left : left + target_size] = texture
        frames.append(np.clip(frame, 0, 255).astype(np.uint8))
        boxes.append((left, top, target_size, target_size))
    return GeneratedSequence(frames=frames, boxes=np.array(boxes, dtype=np.float64))


def passing_distractor_sequence(
    num_frames: int = 70,
    size_hw: tuple[int, int] = (200, 360),
    target_size: int = 36,
    crossing_frames: tuple[int, int] = (20, 50),
    seed: int = 5,
) -> GeneratedSequence:
    """A target drifting slowly right while a look-alike (the same colours and border, another
    pattern) crosses it right to left, in front of it, between `crossing_frames`; the look-alike
    then goes on left, so a tracker that followed it ends far from the target."""
    rng = np.random.default_rng(seed)
    height, width = size_hw
    background = _clutter(rng, height, width)
    texture = _target_texture(rng, target_size)
    lookalike = _target_texture(rng, target_size)
    first, last = crossing_frames
    cy = height // 2
    frames, boxes = [], []
    for index in range(num_frames):
        target_x = width * 0.45 + 0.3 * index
        # The look-alike meets the target at the middle of the crossing frames.
        speed = 2.0 * target_size / max(last - first, 1)
        meet = (first + last) / 2.0
        lookalike_x = width * 0.45 + 0.3 * meet - speed * (index - meet)
        frame = background.copy()
        for x, pattern in ((target_x, texture), (lookalike_x, lookalike)):
            left, top = int(round(x - target_size / 2)), cy - target_size // 2
            lo, hi = max(left, 0), min(left + target_size, width)
            if hi > lo:
                frame[top : top + target_size, lo:hi] = pattern[:, lo - left : hi - left]
        frames.append(np.clip(frame, 0, 255).astype(np.uint8))
        boxes.append(
            (round(target_x - target_size / 2), cy - target_size // 2, target_size, target_size)
        )
    return GeneratedSequence(frames=frames, boxes=np.array(boxes, dtype=np.float64))


def appearing_twin_sequence(
    num_frames: int = 40,
    size_hw: tuple[int, int] = (240, 480),
    target_size: int = 36,
    speed: float = 6.0,
    twin_from: int = 20,
    change: float = 0.4,
    seed: int = 5,
) -> GeneratedSequence:
    """A target moving right at `speed` px per frame; at frame `twin_from` its pattern changes
    (blended by `change` with another one) and a twin with its first pattern appears, still,
    one target side below the target's new position, off its path. The twin matches what every
    appearance model learnt better than the target does (the mechanism of DTB70/Animal3); only
    the target's motion tells them apart."""
    rng = np.random.default_rng(seed)
    height, width = size_hw
    background = _clutter(rng, height, width)
    texture = _target_texture(rng, target_size)
    changed = (1.0 - change) * texture + change * _target_texture(rng, target_size)
    top = height // 2 - target_size
    twin_left = int(round(40.0 + speed * twin_from - target_size / 2))
    frames, boxes = [], []
    for index in range(num_frames):
        left = int(round(40.0 + speed * index - target_size / 2))
        frame = background.copy()
        if index >= twin_from:
            twin_rows = slice(top + target_size, top + 2 * target_size)
            frame[twin_rows, twin_left : twin_left + target_size] = texture
        pattern = changed if index >= twin_from else texture
        frame[top : top + target_size, left : left + target_size] = pattern
        frames.append(np.clip(frame, 0, 255).astype(np.uint8))
        boxes.append((left, top, target_size, target_size))
    return GeneratedSequence(frames=frames, boxes=np.array(boxes, dtype=np.float64))


def spinning_target_sequence(
    num_frames: int = 36,
    size_hw: tuple[int, int] = (240, 320),
    target_hw: tuple[int, int] = (36, 60),
    degrees_per_frame: float = 7.0,
    seed: int = 5,
) -> GeneratedSequence:
    """An elongated textured target drifting right while it turns in the image plane,
    `degrees_per_frame` counter-clockwise as displayed (a yawing drone's view of a vehicle).

    The boxes are the bound of the ellipse inscribed in the turned target (as the tracker
    reports, rotation.bounding_size); `angles` holds the true angle of each frame.
    """
    rng = np.random.default_rng(seed)
    height, width = size_hw
    background = _clutter(rng, height, width)
    texture = cv2.resize(_target_texture(rng, 64), (target_hw[1], target_hw[0]))
    frames, boxes, angles = [], [], []
    for index in range(num_frames):
        angle = degrees_per_frame * index
        cx, cy = width * 0.35 + 1.5 * index, height * 0.5
        turn = cv2.getRotationMatrix2D((target_hw[1] / 2 - 0.5, target_hw[0] / 2 - 0.5), angle, 1)
        turn[:, 2] += (cx - target_hw[1] / 2, cy - target_hw[0] / 2)
        layer = cv2.warpAffine(texture, turn, (width, height), flags=cv2.INTER_LINEAR)
        mask = cv2.warpAffine(np.ones(target_hw, np.float32), turn, (width, height))[:, :, None]
        frame = background * (1 - mask) + layer * mask
        frames.append(np.clip(frame, 0, 255).astype(np.uint8))
        radians = np.radians(angle)
        cos, sin = abs(np.cos(radians)), abs(np.sin(radians))
        box_h = np.hypot(target_hw[0] * cos, target_hw[1] * sin)
        box_w = np.hypot(target_hw[1] * cos, target_hw[0] * sin)
        boxes.append((cx - box_w / 2, cy - box_h / 2, box_w, box_h))
        angles.append(angle)
    return GeneratedSequence(frames=frames, boxes=np.array(boxes), angles=np.array(angles))
