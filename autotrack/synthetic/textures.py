"""Procedural textures of the synthetic room: floor, walls with posters, ceiling and the
landmark patterns, all seeded."""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

from autotrack.errors import InputError

TEXEL_M = 0.005

LANDMARK_TEXELS = 256


def smooth_noise(
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


def shade(base_bgr: Sequence[float], variation: np.ndarray, strength: float) -> np.ndarray:
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
    image *= (1.0 + 0.08 * smooth_noise(rng, height, width, 120))[:, :, None]
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
    image = shade(
        paints[int(rng.integers(len(paints)))], smooth_noise(rng, height, width, 200), 0.05
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
    image = shade((215, 218, 220), smooth_noise(rng, height, width, 60), 0.04)
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
