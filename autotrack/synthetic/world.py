"""The room of the synthetic test bed: its size, the four landmarks and their stands, the
default camera and scene, and the textured planes the renderer draws."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from autotrack.errors import InputError
from autotrack.localization.camera import CameraIntrinsics, project_points
from autotrack.localization.scene import Landmark, Scene
from autotrack.synthetic.textures import (
    ceiling_texture,
    floor_texture,
    landmark_texture,
    shade,
    smooth_noise,
    wall_texture,
)

ROOM_X = (-3.5, 3.5)


ROOM_Y = (-3.0, 7.0)


ROOM_HEIGHT = 3.0


STAND_BOARD_HALF_M = 0.2


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
    room = _room_planes(rng)  # textures draw from rng in this order: room, then landmarks
    return room, _landmark_objects(rng)


def _room_planes(rng: np.random.Generator) -> list[TexturedPlane]:
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
    return room


def _landmark_objects(rng: np.random.Generator) -> list[list[TexturedPlane]]:
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
        board = shade((150, 150, 145), smooth_noise(rng, 108, 108, 30), 0.08).astype(np.uint8)
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
    return objects
