"""Hard cases for the synthetic test bed: occlusion, a landmark leaving the view, blur, lighting.

Each case is a normal test-bed sequence (autotrack/synthetic/) with one or more events:

- `occlusion`: a flying board (50 x 50 cm) crosses in front of one landmark, hiding it for
  about 2 s;
- `leave_view`: the camera turns away (a yaw of some 30 deg and back), taking one landmark out
  of the image for about 1.5 s;
- `occlusion_and_turn`: both, on different landmarks, a few seconds apart;
- `blur_bursts`: long exposures (150 ms) over a third of the frames;
- `lighting`: the lights drop to 40 % with a harder gamma for 3 s, in one step each way.

Besides the usual files (img/, scene.json, boxes.json, poses_gt.tum, groundtruth/,
sequence.json), each folder gets `visibility.csv`: per frame and landmark, the fraction of the
landmark square that is inside the image and not behind the board (0-1), the ground truth for
"hidden" (< 0.5) and "back in view" (>= 0.99).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from autotrack.errors import InputError
from autotrack.io.atomic import write_image, write_text
from autotrack.localization.camera import project_points
from autotrack.synthetic.renderer import Renderer, blur_vector, write_sequence_truth
from autotrack.synthetic.trajectories import (
    RenderSettings,
    SequenceSpec,
    frame_conditions,
    yaw_pitch,
)
from autotrack.synthetic.world import (
    LANDMARK_LAYOUT,
    default_camera,
    default_scene,
    landmark_box,
    landmark_corners,
    make_plane,
)

CASES = ("occlusion", "leave_view", "occlusion_and_turn", "blur_bursts", "lighting")
"""The hard cases, in the order the benchmark table lists them."""

HIDDEN_FRACTION = 0.5
"""A landmark with less than this fraction of its square visible counts as hidden."""
BACK_FRACTION = 0.99
"""A hidden landmark counts as back in view from the first frame with this fraction visible."""


@dataclass(frozen=True)
class Occluder:
    """A board flying past in front of a landmark."""

    landmark: str
    """The landmark it crosses in front of."""
    start_s: float
    """Time (s) the board's centre is level with the landmark (as seen from the camera)."""
    distance_m: float = 0.6
    """How far in front of the landmark (towards the camera, metres) the board flies."""
    speed_m_s: float = -0.3
    """Speed across the line of sight along world x (metres per second; negative: to the left)."""
    width_m: float = 0.5
    """Board width (metres)."""
    height_m: float = 0.5
    """Board height (metres)."""


@dataclass(frozen=True)
class Turn:
    """The camera yaws away and back."""

    start_s: float
    """Time (s) the turn starts."""
    yaw_deg: float
    """Largest extra yaw (degrees; positive turns left, so landmarks leave on the right)."""
    pitch_deg: float = 0.0
    """Largest extra pitch at the same time (degrees; positive looks up... see `yaw_pitch`)."""
    ramp_s: float = 1.0
    """Time to turn away and, later, back (seconds)."""
    hold_s: float = 1.2
    """Time held at the largest yaw (seconds)."""

    def angles_rad(self, t: float) -> tuple[float, float]:
        """Extra (yaw, pitch) at time t (smooth cosine ramps)."""
        t0 = self.start_s
        t1, t2, t3 = (
            t0 + self.ramp_s,
            t0 + self.ramp_s + self.hold_s,
            t0 + 2 * self.ramp_s + self.hold_s,
        )
        if t <= t0 or t >= t3:
            fraction = 0.0
        elif t < t1:
            fraction = 0.5 - 0.5 * math.cos(math.pi * (t - t0) / self.ramp_s)
        elif t <= t2:
            fraction = 1.0
        else:
            fraction = 0.5 + 0.5 * math.cos(math.pi * (t - t2) / self.ramp_s)
        return math.radians(self.yaw_deg) * fraction, math.radians(self.pitch_deg) * fraction


@dataclass(frozen=True)
class LightStep:
    """The lights drop for a while, in one step each way."""

    start_s: float
    """Time (s) the lights drop."""
    duration_s: float
    """How long they stay low (seconds)."""
    gain: float = 0.4
    """Brightness factor while low."""
    gamma: float = 1.35
    """Extra gamma while low (contrast of the darker image)."""


@dataclass(frozen=True)
class ScenarioSpec:
    """A test-bed sequence with events."""

    case: str
    """One of CASES (the folder name)."""
    sequence: SequenceSpec
    """The underlying trajectory, frame count, seed and image formation."""
    occluders: tuple[Occluder, ...] = ()
    """Boards flying past."""
    turns: tuple[Turn, ...] = ()
    """Camera turns."""
    light_steps: tuple[LightStep, ...] = ()
    """Lighting steps."""

    def camera_path(self) -> Callable[[float], tuple[np.ndarray, np.ndarray]]:
        """Camera pose as a function of time: the trajectory plus the turns."""
        base = self.sequence.camera_path()
        turns = self.turns

        def pose(t: float) -> tuple[np.ndarray, np.ndarray]:
            rotation, position = base(t)
            for turn in turns:
                yaw, pitch = turn.angles_rad(t)
                if yaw or pitch:
                    rotation = yaw_pitch(rotation, yaw, pitch)
            return rotation, position

        return pose


def scenario_specs(seed: int = 0, frames: int = 250) -> list[ScenarioSpec]:
    """The five hard cases (CASES order), each `frames` long (at least 200)."""
    if frames < 200:
        raise InputError("the hard cases need at least 200 frames (events at 6-16 s)")
    settings = RenderSettings()

    def base(k: int, trajectory: str, **changes) -> SequenceSpec:
        return SequenceSpec(
            CASES[k], trajectory, frames, seed * 1000 + 100 + k, replace(settings, **changes)
        )

    return [
        ScenarioSpec(CASES[0], base(0, "circle"), occluders=(Occluder("C", 8.0, speed_m_s=0.3),)),
        ScenarioSpec(CASES[1], base(1, "figure_eight"), turns=(Turn(7.0, 18.0, hold_s=1.5),)),
        ScenarioSpec(
            CASES[2],
            base(2, "lateral_sweep"),
            occluders=(Occluder("A", 6.0, speed_m_s=0.3),),
            turns=(Turn(12.0, 0.0, pitch_deg=13.0),),
        ),
        ScenarioSpec(
            CASES[3], base(3, "approach_retreat", burst_exposure_s=0.15, burst_fraction=0.33)
        ),
        ScenarioSpec(CASES[4], base(4, "climb_yaw"), light_steps=(LightStep(8.0, 3.0),)),
    ]


# ---------------------------------------------------------------------------------------------
# Geometry of the events


def occluder_corners(occluder: Occluder, t: float, camera_position: np.ndarray) -> np.ndarray:
    """World corners (4, 3) of the board at time t. It flies in the plane `distance_m` in front of
    its landmark (towards the camera, along world y), crossing the camera's line of sight to the
    landmark at `speed_m_s` along world x, centred on it at `start_s`."""
    centre = np.array(LANDMARK_LAYOUT[occluder.landmark].centre)
    plane_y = centre[1] - occluder.distance_m
    fraction = (plane_y - camera_position[1]) / (centre[1] - camera_position[1])
    anchor = camera_position + fraction * (centre - camera_position)
    x = anchor[0] + occluder.speed_m_s * (t - occluder.start_s)
    half_w, half_h = occluder.width_m / 2, occluder.height_m / 2
    z = anchor[2]
    return np.array(
        [
            [x - half_w, plane_y, z + half_h],
            [x + half_w, plane_y, z + half_h],
            [x + half_w, plane_y, z - half_h],
            [x - half_w, plane_y, z - half_h],
        ]
    )


def board_texture(rng: np.random.Generator) -> np.ndarray:
    """A cardboard-like panel with a few dark stripes (BGR uint8, 110 x 90 texels)."""
    board = np.full((110, 90, 3), (120, 150, 175), np.float32)
    board *= 1.0 + 0.08 * rng.standard_normal((110, 90, 1)).astype(np.float32)
    for row in range(10, 110, 25):
        board[row : row + 4] *= 0.5
    return np.clip(board, 0, 255).astype(np.uint8)


def visible_fraction(
    camera_projected: np.ndarray, width: int, height: int, occluders: list[np.ndarray]
) -> float:
    """Fraction of a projected convex quadrilateral inside the image and not covered by any of
    the (nearer) projected occluder quadrilaterals (occluders assumed not to overlap)."""
    square = camera_projected.astype(np.float32).reshape(-1, 2)
    area = abs(cv2.contourArea(square))
    if area <= 0:
        return 0.0
    image = np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]], np.float32)
    inside, polygon = cv2.intersectConvexConvex(square, image)
    if inside <= 0 or polygon is None:
        return 0.0
    covered = 0.0
    for occluder in occluders:
        hidden, _ = cv2.intersectConvexConvex(polygon.reshape(-1, 2), occluder.astype(np.float32))
        covered += max(float(hidden), 0.0)
    return float(np.clip((inside - covered) / area, 0.0, 1.0))


def visibility(
    spec: ScenarioSpec, rotations: np.ndarray, positions: np.ndarray
) -> dict[str, np.ndarray]:
    """Per landmark, the visible fraction of its square in every frame (pinhole geometry)."""
    camera = default_camera(spec.sequence.settings.width, spec.sequence.settings.height)
    fps = spec.sequence.settings.fps
    out = {k: np.zeros(len(positions)) for k in LANDMARK_LAYOUT}
    for frame, (rotation, position) in enumerate(zip(rotations, positions, strict=True)):
        t = frame / fps
        forward = rotation[:, 2]
        boards = []
        for occluder in spec.occluders:
            corners = occluder_corners(occluder, t, position)
            if np.all((corners - position) @ forward > 0.05):
                boards.append((corners, project_points(camera, corners, rotation, position)))
        for landmark_id in LANDMARK_LAYOUT:
            corners = landmark_corners(landmark_id)
            depth = float((np.array(LANDMARK_LAYOUT[landmark_id].centre) - position) @ forward)
            if depth <= 0.05:
                continue
            nearer = [
                projected
                for board, projected in boards
                if float((board.mean(axis=0) - position) @ forward) < depth
            ]
            projected = project_points(camera, corners, rotation, position)
            out[landmark_id][frame] = visible_fraction(
                projected, camera.width, camera.height, nearer
            )
    return out


def hidden_spans(fraction: np.ndarray) -> list[tuple[int, int]]:
    """(first hidden frame, first frame back in view) for each run of hidden frames; the second
    is len(fraction) when the landmark never comes back."""
    spans = []
    frame = 0
    count = len(fraction)
    while frame < count:
        if fraction[frame] < HIDDEN_FRACTION:
            start = frame
            while frame < count and fraction[frame] < BACK_FRACTION:
                frame += 1
            spans.append((start, frame))
        frame += 1
    return spans


# ---------------------------------------------------------------------------------------------
# Rendering


def render_scenario(
    out_dir: str | Path,
    spec: ScenarioSpec,
    progress: Callable[[int], None] | None = None,
) -> Path:
    """Render one hard case into `out_dir` (the test-bed layout plus visibility.csv and the events
    in sequence.json). Returns the folder."""
    sequence = spec.sequence
    settings = sequence.settings
    out = Path(out_dir)
    camera = default_camera(settings.width, settings.height, settings.distortion)
    scene = default_scene(camera)
    path = spec.camera_path()
    timestamps = np.arange(sequence.frames) / settings.fps
    poses = [path(float(t)) for t in timestamps]
    rotations = np.stack([r for r, _ in poses])
    positions = np.stack([p for _, p in poses])
    fractions = visibility(spec, rotations, positions)
    (out / "img").mkdir(parents=True, exist_ok=True)
    (out / "groundtruth").mkdir(exist_ok=True)
    for stale in [*(out / "img").glob("*.jpg"), *(out / "groundtruth").glob("*.txt")]:
        stale.unlink()
    boxes = {k: [landmark_box(camera, k, r, p) for r, p in poses] for k in LANDMARK_LAYOUT}
    write_sequence_truth(out, scene, boxes, timestamps, rotations, positions)
    _write_case_files(out, spec, fractions)

    renderer = Renderer(camera, sequence.seed, settings.noise_sigma)
    scenery = list(renderer.objects)
    board_rng = np.random.default_rng(sequence.seed + 31)
    boards = [
        make_plane("board", (0, 0, 0), (1, 0, 0), (0, 0, -1), board_texture(board_rng), True)
        for _ in spec.occluders
    ]
    conditions = frame_conditions(sequence)
    gain, gamma = conditions.gain.copy(), conditions.gamma.copy()
    for step in spec.light_steps:
        low = (timestamps >= step.start_s) & (timestamps < step.start_s + step.duration_s)
        gain[low] *= step.gain
        gamma[low] *= step.gamma
    rng = np.random.default_rng(sequence.seed + 15485863)
    for index in range(sequence.frames):
        t = float(timestamps[index])
        position = positions[index]
        flying = []
        for occluder, board in zip(spec.occluders, boards, strict=True):
            c = occluder_corners(occluder, t, position)
            flying.append([replace(board, origin=c[0], u_axis=c[1] - c[0], v_axis=c[3] - c[0])])
        renderer.objects = scenery + flying
        blur = blur_vector(camera, path, t, float(conditions.exposure_s[index]))
        frame = renderer.render(
            rotations[index],
            position,
            blur_px=blur,
            gain=float(gain[index]),
            gamma=float(gamma[index]),
            noise_index=index,
            noise_offset=(int(rng.integers(0, 64)), int(rng.integers(0, 64))),
        )
        target = out / "img" / f"{index + 1:05d}.jpg"
        write_image(target, frame, [cv2.IMWRITE_JPEG_QUALITY, settings.jpeg_quality])
        if progress is not None:
            progress(1)
    return out


def _write_case_files(out: Path, spec: ScenarioSpec, fractions: dict[str, np.ndarray]) -> None:
    """visibility.csv and sequence.json (with the case's events) of a hard case."""
    sequence, settings = spec.sequence, spec.sequence.settings
    ids = list(LANDMARK_LAYOUT)
    rows = ["frame," + ",".join(ids)]
    rows += [
        f"{k}," + ",".join(f"{fractions[i][k]:.3f}" for i in ids) for k in range(sequence.frames)
    ]
    write_text(out / "visibility.csv", "\n".join(rows) + "\n")
    metadata = {
        "name": spec.case,
        "case": spec.case,
        "trajectory": sequence.trajectory,
        "frames": sequence.frames,
        "fps": settings.fps,
        "seed": sequence.seed,
        "width": settings.width,
        "height": settings.height,
        "hidden": {k: hidden_spans(fractions[k]) for k in ids if hidden_spans(fractions[k])},
        "occluders": [vars(o) for o in spec.occluders],
        "turns": [vars(t) for t in spec.turns],
        "light_steps": [vars(s) for s in spec.light_steps],
        "boxes": "x,y,w,h, 0-based pixels (the top-left pixel's centre is (0, 0))",
        "poses": "TUM, camera-to-world, OpenCV camera axes (x right, y down, z forward)",
    }
    write_text(out / "sequence.json", json.dumps(metadata, indent=2) + "\n")


def read_visibility(folder: str | Path) -> dict[str, np.ndarray]:
    """visibility.csv of a rendered hard case: landmark id -> (n,) visible fraction."""
    path = Path(folder) / "visibility.csv"
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as error:
        raise InputError(f"cannot read {path}: {error.strerror or error}") from None
    ids = lines[0].split(",")[1:]
    table = np.array([[float(v) for v in line.split(",")[1:]] for line in lines[1:]])
    return {landmark_id: table[:, k] for k, landmark_id in enumerate(ids)}
