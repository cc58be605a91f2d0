"""Aerial scenes for the tracker: small targets among look-alikes, seen from a drone, top-down.

The room of the test bed (world.py, renderer.py) has four well-textured planar landmarks; the
UAV benchmarks' hard cases are different: a vehicle on a road with others like it passing, a
walker inside a group of walkers, a vehicle a dozen pixels long. These scenes render those in a
few milliseconds a frame, with the target's exact box:

- `road_lookalikes`: a car driving along a road while cars of the same make and colour pass
  it in the next lane, one after the other, overlapping its search region;
- `walker_group`: a walker in a tight group of walkers dressed alike, all walking together;
- `tiny_vehicle`: an 11 x 8 px car driving along a road with a few other cars, the camera
  drifting.
- `walker_crowd`: a walker entering a crowd of walkers in other clothes, one of them passing
  over it.

A scene is a textured ground (asphalt with lane markings and verges, or paving) seen by a
camera that drifts slowly over it, and movers (vehicle or walker sprites) that move at a
constant velocity plus an optional sway. The first mover is the target. Frames are RGB uint8.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from autotrack.errors import InputError
from autotrack.synthetic.textures import smooth_noise

SUPERSAMPLE = 4
"""Sprites are drawn at this many texels per pixel of their size and area-averaged down."""


@dataclass(frozen=True)
class Mover:
    """An object moving over the ground at a constant velocity plus a sway."""

    kind: str
    """'vehicle' (a car from above, front to the right) or 'walker' (a person, head up)."""
    size_hw: tuple[float, float]
    """(height, width) of its box (pixels)."""
    start_xy: tuple[float, float]
    """Centre (x, y) at frame 0 in the first frame's pixels (0-based); the road's middle is
    at y = height / 2 on the middle frame."""
    velocity_xy: tuple[float, float]
    """Motion per frame (ground pixels)."""
    colour_rgb: tuple[int, int, int]
    """Main colour (body paint; a walker's shirt)."""
    sway_px: float = 0.0
    """Amplitude of a sideways sine sway (pixels, perpendicular to the motion)."""
    sway_period: float = 20.0
    """Frames per sway period."""
    phase: float = 0.0
    """Sway phase (radians); walkers also use it for their stride."""

    def centre(self, frame: int) -> tuple[float, float]:
        """Centre (x, y) on the ground at `frame`."""
        x = self.start_xy[0] + self.velocity_xy[0] * frame
        y = self.start_xy[1] + self.velocity_xy[1] * frame
        if self.sway_px:
            speed = math.hypot(*self.velocity_xy) or 1.0
            normal = (-self.velocity_xy[1] / speed, self.velocity_xy[0] / speed)
            offset = self.sway_px * math.sin(2 * math.pi * frame / self.sway_period + self.phase)
            x, y = x + normal[0] * offset, y + normal[1] * offset
        return x, y


@dataclass(frozen=True)
class AerialSpec:
    """One aerial scene: ground, camera drift, movers (the first is the target)."""

    name: str
    """Scene name (the test's sequence name)."""
    ground: str
    """'road' (asphalt, two lanes, dashed markings, grass verges) or 'paving'."""
    movers: tuple[Mover, ...]
    """The objects; movers[0] is the target whose box is the ground truth."""
    frames: int = 80
    """Number of frames."""
    width: int = 320
    """Frame width (pixels)."""
    height: int = 240
    """Frame height (pixels)."""
    drift_xy: tuple[float, float] = (0.0, 0.0)
    """Camera motion over the ground per frame (pixels)."""
    zoom_per_frame: float = 1.0
    """The camera descends: everything grows by this factor a frame about the view's centre."""
    shake_px: float = 0.0
    """Camera shake: a smooth random offset of about this many pixels added to the drift."""
    shadows: tuple[tuple[float, float], ...] = ()
    """Bands of shade across the road (x from, x to, in the first frame's pixels, moving with
    the ground), where the ground and the movers are lit at `shadow_gain`."""
    shadow_gain: float = 0.5
    """Brightness in a shadow."""
    trees: tuple[tuple[float, float], ...] = ()
    """Bands of tree canopy over the road (x from, x to, first frame's pixels, moving with the
    ground), drawn over the movers: whatever passes under them is hidden."""
    noise_sigma: float = 2.0
    """Sensor noise (grey levels)."""
    seed: int = 0
    """Seed of the textures and the noise."""


@dataclass(frozen=True)
class AerialSequence:
    """Rendered frames and the target's box on each."""

    name: str
    """The scene's name."""
    frames: list[np.ndarray]
    """RGB uint8 frames."""
    boxes: np.ndarray
    """(frames, 4) target boxes (x, y, w, h), 0-based pixels."""


def _ground(kind: str, rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    """Ground texture (RGB float32): a road along x centred on the texture, or paving."""
    fine = smooth_noise(rng, height, width, cell_texels=3.0)
    coarse = smooth_noise(rng, height, width, cell_texels=40.0)
    if kind == "paving":
        base = np.array([150, 140, 125], np.float32)
        ground = base * (1.0 + 0.10 * fine[..., None] + 0.08 * coarse[..., None])
        joints = (np.arange(width) % 17 == 0)[None, :] | (np.arange(height) % 17 == 0)[:, None]
        ground[joints] *= 0.8
        return ground
    grass = np.array([70, 105, 50], np.float32) * (1.0 + 0.25 * fine[..., None])
    asphalt = np.array([95, 95, 98], np.float32) * (1.0 + 0.08 * fine[..., None])
    ground = grass * (1.0 + 0.2 * coarse[..., None])
    middle = height // 2
    half_road = 26
    rows = slice(middle - half_road, middle + half_road)
    ground[rows] = asphalt[rows] * (1.0 + 0.05 * coarse[rows, :, None])
    dashes = (np.arange(width) % 24) < 12
    ground[middle - 1 : middle + 1, dashes] = (200, 200, 195)
    for edge in (middle - half_road + 2, middle + half_road - 3):
        ground[edge : edge + 1] = (185, 185, 180)
    return ground


def _vehicle_sprite(size_hw: tuple[float, float], colour, rng) -> np.ndarray:
    """RGBA float32 sprite of a car seen from above, front to the right (supersampled)."""
    rows = max(int(round(size_hw[0] * SUPERSAMPLE)), 4)
    cols = max(int(round(size_hw[1] * SUPERSAMPLE)), 4)
    sprite = np.zeros((rows, cols, 4), np.float32)
    radius = max(min(rows, cols) // 4, 1)
    body = np.zeros((rows, cols), np.uint8)
    cv2.rectangle(body, (radius, 0), (cols - 1 - radius, rows - 1), 1, -1)
    cv2.rectangle(body, (0, radius), (cols - 1, rows - 1 - radius), 1, -1)
    for cx, cy in ((radius, radius), (cols - 1 - radius, radius)):
        cv2.circle(body, (cx, cy), radius, 1, -1)
        cv2.circle(body, (cx, rows - 1 - cy), radius, 1, -1)
    paint = np.array(colour, np.float32) * (1.0 + 0.04 * rng.standard_normal(3))
    sprite[..., :3] = paint
    # Windscreen (dark, towards the front), roof (lighter), rear window (dark).
    inset = rows // 6
    windscreen = slice(int(cols * 0.58), int(cols * 0.72))
    rear = slice(int(cols * 0.16), int(cols * 0.26))
    sprite[inset:-inset, windscreen, :3] = (35, 40, 50)
    sprite[inset:-inset, rear, :3] = (45, 50, 60)
    sprite[inset:-inset, int(cols * 0.30) : int(cols * 0.55), :3] = np.minimum(paint * 1.2, 255)
    sprite[..., 3] = body
    return sprite


def _walker_sprite(size_hw: tuple[float, float], colour, rng, stride: float) -> np.ndarray:
    """RGBA float32 sprite of a walker seen from a drone at an angle (head up, supersampled);
    `stride` in [-1, 1] opens the legs."""
    rows = max(int(round(size_hw[0] * SUPERSAMPLE)), 6)
    cols = max(int(round(size_hw[1] * SUPERSAMPLE)), 4)
    mask = np.zeros((rows, cols), np.uint8)
    sprite = np.zeros((rows, cols, 4), np.float32)
    centre = cols // 2
    head = max(rows // 9, 1)
    shirt = np.array(colour, np.float32) * (1.0 + 0.05 * rng.standard_normal(3))
    cv2.circle(mask, (centre, head + 1), head, 1, -1)
    sprite[: 2 * head + 2, :, :3] = (60, 45, 35)  # hair
    torso_top, torso_bottom = 2 * head + 1, int(rows * 0.6)
    cv2.rectangle(mask, (cols // 6, torso_top), (cols - 1 - cols // 6, torso_bottom), 1, -1)
    sprite[2 * head + 2 : torso_bottom + 1, :, :3] = shirt
    leg = max(cols // 5, 1)
    spread = int(stride * cols / 5)
    for side in (-1, 1):
        foot = centre + side * (cols // 5) + side * spread
        cv2.line(mask, (centre + side * (cols // 6), torso_bottom), (foot, rows - 1), 1, leg)
    sprite[torso_bottom + 1 :, :, :3] = (40, 45, 70)  # trousers
    sprite[..., 3] = mask
    return sprite


def _blend(canvas: np.ndarray, sprite: np.ndarray, box_xywh: tuple[float, ...]) -> None:
    """Draw a supersampled RGBA sprite into `canvas` (RGB float32) filling `box_xywh`."""
    x, y, w, h = box_xywh
    sx, sy = w / sprite.shape[1], h / sprite.shape[0]
    # Texel centre u maps to x - 0.5 + (u + 0.5) sx (box edges at x - 0.5 .. x + w - 0.5).
    blurred = cv2.GaussianBlur(sprite, (0, 0), SUPERSAMPLE / 2.5)
    matrix = np.array([[sx, 0.0, x - 0.5 + 0.5 * sx], [0.0, sy, y - 0.5 + 0.5 * sy]])
    size = (canvas.shape[1], canvas.shape[0])
    warped = cv2.warpAffine(blurred, matrix, size, flags=cv2.INTER_LINEAR, borderValue=0)
    alpha = warped[..., 3:4]
    canvas *= 1.0 - alpha
    canvas += warped[..., :3] * alpha


def _band(start: float, end: float, width: int) -> tuple[int, int]:
    """Columns [left, right) of a band from x = start to end, clipped to a view `width` wide."""
    left = min(max(int(round(start)), 0), width)
    return left, min(max(int(round(end)), left), width)


def _canopy(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    """Foliage texture (RGB float32) for the tree bands."""
    leaves = smooth_noise(rng, height, width, cell_texels=5.0)
    return np.array([45, 80, 35], np.float32) * (1.0 + 0.45 * leaves[..., None])


def _zoomed(view: np.ndarray, box: tuple[float, ...], zoom: float):
    """The view magnified by `zoom` about its centre, and the box moved and scaled with it."""
    centre = np.array([(view.shape[1] - 1) / 2.0, (view.shape[0] - 1) / 2.0])
    matrix = np.array([[zoom, 0.0, centre[0] * (1 - zoom)], [0.0, zoom, centre[1] * (1 - zoom)]])
    size = (view.shape[1], view.shape[0])
    zoomed = cv2.warpAffine(view, matrix, size, flags=cv2.INTER_AREA, borderMode=cv2.BORDER_REFLECT)
    x, y, w, h = box
    middle = centre + zoom * (np.array([x + w / 2 - 0.5, y + h / 2 - 0.5]) - centre)
    w, h = w * zoom, h * zoom
    return zoomed, (middle[0] - w / 2 + 0.5, middle[1] - h / 2 + 0.5, w, h)


def _shake(rng: np.random.Generator, frames: int, amplitude: float) -> np.ndarray:
    """(frames, 2) smooth random camera offsets (x, y) within about +-`amplitude` pixels."""
    if not amplitude:
        return np.zeros((frames, 2))
    steps = rng.standard_normal((frames + 4, 2))
    smooth = np.stack([np.convolve(steps[:, k], np.ones(5) / 5, "valid") for k in (0, 1)], 1)
    return amplitude * smooth[:frames] / max(float(np.abs(smooth).max()), 1e-9)


def render_aerial(spec: AerialSpec) -> AerialSequence:
    """Render a scene: the frames (RGB uint8) and the target's boxes."""
    if spec.frames < 2 or not spec.movers:
        raise InputError("an aerial scene needs at least 2 frames and one mover")
    rng = np.random.default_rng(spec.seed)
    reach = np.abs(np.array(spec.drift_xy)) * spec.frames + 2 * spec.shake_px
    ground_h = spec.height + int(math.ceil(reach[1])) + 2
    ground_w = spec.width + int(math.ceil(reach[0])) + 2
    ground = _ground(spec.ground, rng, ground_h, ground_w)
    # The camera's top-left corner on the ground at frame 0: the view stays on the ground and
    # the road (the ground's middle row) crosses the view's middle half-way through.
    origin = np.array(
        [
            reach[0] - spec.shake_px if spec.drift_xy[0] < 0 else spec.shake_px,
            (ground_h - spec.height) / 2 - spec.drift_xy[1] * spec.frames / 2,
        ]
    )
    vehicles = {
        k: _vehicle_sprite(m.size_hw, m.colour_rgb, np.random.default_rng(spec.seed + 10 + k))
        for k, m in enumerate(spec.movers)
        if m.kind == "vehicle"
    }
    canopy = _canopy(np.random.default_rng(spec.seed + 4), ground_h, ground_w)
    noise_rng = np.random.default_rng(spec.seed + 2)
    shake = _shake(np.random.default_rng(spec.seed + 3), spec.frames, spec.shake_px)
    frames, boxes = [], []
    for index in range(spec.frames):
        drift = np.array(spec.drift_xy) * index + shake[index]
        camera = origin + drift
        shift = np.array([[1.0, 0.0, camera[0]], [0.0, 1.0, camera[1]]])
        view = cv2.warpAffine(
            ground,
            shift,
            (spec.width, spec.height),
            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
            borderMode=cv2.BORDER_REFLECT,
        )
        for k, mover in enumerate(spec.movers):
            mx, my = mover.centre(index)
            cx, cy = mx - drift[0], my - drift[1]
            h, w = mover.size_hw
            box = (cx - w / 2 + 0.5, cy - h / 2 + 0.5, float(w), float(h))
            if mover.kind == "vehicle":
                sprite = vehicles[k]
            else:
                stride = math.sin(2 * math.pi * index / 8.0 + mover.phase)
                jitter = np.random.default_rng(spec.seed + 10 + k)  # the same clothes every frame
                sprite = _walker_sprite(mover.size_hw, mover.colour_rgb, jitter, stride)
            _blend(view, sprite, box)
            if k == 0:
                boxes.append(box)
        for start, end in spec.shadows:
            left, right = _band(start - drift[0], end - drift[0], spec.width)
            view[:, left:right] *= spec.shadow_gain
        for start, end in spec.trees:
            left, right = _band(start - drift[0], end - drift[0], spec.width)
            top, column = int(camera[1]), int(camera[0])
            view[:, left:right] = canopy[top : top + spec.height, left + column : right + column]
        if spec.zoom_per_frame != 1.0:
            view, box = _zoomed(view, boxes[-1], spec.zoom_per_frame**index)
            boxes[-1] = box
        view += noise_rng.normal(0.0, spec.noise_sigma, view.shape).astype(np.float32)
        frames.append(np.clip(view, 0, 255).astype(np.uint8))
    return AerialSequence(spec.name, frames, np.array(boxes))


SCENES = ("road_lookalikes", "walker_group", "tiny_vehicle", "walker_crowd")
"""The aerial scenes, each a failure pattern of trackers on UAV sequences (module docstring)."""

RED_CAR = (170, 30, 35)
SILVER_CAR = (200, 200, 205)
CROWD = (  # walker_crowd: (start (x, y), velocity (x, y), shirt colour); the target first
    ((160.0, 110.0), (0.8, 0.6), (40, 90, 160)),
    ((151.7, 81.8), (0.69, 0.84), (167, 102, 123)),
    ((151.9, 89.9), (0.71, 0.22), (138, 163, 163)),
    ((180.7, 135.4), (0.61, 0.47), (156, 73, 35)),
    ((157.3, 85.6), (0.85, 0.81), (61, 73, 77)),
    ((161.4, 88.7), (0.84, 0.21), (50, 79, 151)),
    ((150.4, 86.8), (1.08, 0.53), (113, 48, 98)),
    ((152.5, 109.5), (1.01, 0.38), (91, 154, 65)),
    ((157.0, 87.2), (0.43, 0.49), (32, 181, 156)),
)


def aerial_scene(name: str, seed: int = 1) -> AerialSpec:
    """One of SCENES (320 x 240, 80 frames at ~10 fps motion), with textures and noise by `seed`.

    - road_lookalikes: a red car (12 x 24 px) drives right in the near lane, the camera
      following it; four red cars like it come the other way in the far lane, 24 px off; the
      target passes under a narrow tree crown (8 px) that hides half of it for a frame or two.
    - walker_group: a walker (9 x 22 px) in the middle of five abreast, 13 px apart, two more
      behind, all dressed alike and walking together, the camera shaking.
    - tiny_vehicle: a silver car of 11 x 8 px behind another like it, two oncoming, the camera
      drifting and shaking; the cars pass under two narrow tree crowns.
    - walker_crowd: a walker (9 x 22 px) with a crowd of six 20-28 px above it, overlapping
      one another, two of them closing in, while a seventh starts 8 px beside it and passes
      over it (0.3 px a frame, up and across) and an eighth walks below; all in different
      clothes, the camera shaking.
    """
    road = 120.0
    if name == "road_lookalikes":
        cars = [Mover("vehicle", (12, 24), (90, road + 12), (3.0, 0.0), RED_CAR)]
        cars += [
            Mover("vehicle", (12, 24), (260 + 70 * k, road - 12), (-3.0, 0.0), RED_CAR)
            for k in range(4)
        ]
        return AerialSpec(
            name, "road", tuple(cars), drift_xy=(2.5, 0.0), trees=((150, 158),),
            shake_px=3.0, noise_sigma=4.0, seed=seed,
        )  # fmt: skip
    if name == "walker_group":
        offsets = ((0, 0), (-13, 0), (13, 0), (-26, 0), (26, 0), (-7, 20), (7, 20))
        walkers = tuple(
            Mover("walker", (22, 9), (160 + dx, 100 + dy), (0.8, 0.6), (40, 90, 160), 1.0, 20.0, k)
            for k, (dx, dy) in enumerate(offsets)
        )
        return AerialSpec(name, "paving", walkers, shake_px=3.0, noise_sigma=4.0, seed=seed)
    if name == "tiny_vehicle":
        cars = (
            Mover("vehicle", (8, 11), (80, road + 10), (4.0, 0.0), SILVER_CAR),
            Mover("vehicle", (8, 11), (300, road - 10), (-3.0, 0.0), SILVER_CAR),
            Mover("vehicle", (8, 11), (40, road + 10), (4.0, 0.0), (195, 195, 200)),
            Mover("vehicle", (8, 12), (400, road - 10), (-3.0, 0.0), (40, 40, 45)),
        )
        return AerialSpec(
            name, "road", cars, drift_xy=(3.0, 0.0), trees=((200, 206), (330, 334)),
            shake_px=3.0, noise_sigma=5.0, seed=seed,
        )  # fmt: skip
    if name == "walker_crowd":
        walkers = tuple(
            Mover("walker", (22, 9), start, velocity, colour, 1.0, 20.0, k)
            for k, (start, velocity, colour) in enumerate(CROWD)
        )
        return AerialSpec(name, "paving", walkers, shake_px=3.0, noise_sigma=4.0, seed=seed)
    raise InputError(f"unknown aerial scene {name!r}; choose one of {', '.join(SCENES)}")
