"""Localisation scene: the calibrated camera and the landmarks' surveyed 3-D positions.

A scene file is JSON (format in docs/localization.md)::

    {
      "camera": {"fx": 920.0, "fy": 920.0, "cx": 639.5, "cy": 359.5,
                 "distortion": [k1, k2, p1, p2, k3], "width": 1280, "height": 720},
      "landmarks": [{"id": "A", "position": [x, y, z], "name": "red rings"}, ...]
    }

Positions are metres in the world frame; the camera follows OpenCV's convention (x right,
y down, z forward; pixel (0, 0) is the centre of the top-left pixel).
"""

from __future__ import annotations

import itertools
import json
import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autotrack.errors import SceneError
from autotrack.io.atomic import write_text
from autotrack.io.ids import checked_identifier
from autotrack.localization.camera import CameraIntrinsics

# Numbers of distortion coefficients OpenCV accepts: (k1 k2 p1 p2 [k3 [k4 k5 k6 [s1..s4 [tx ty]]]]).
DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)
MIN_LANDMARKS = 4

_CAMERA_FIELDS = ("fx", "fy", "cx", "cy", "width", "height")
_LANDMARK_FIELDS = ("id", "position")


@dataclass(frozen=True)
class Landmark:
    """A tracked object of known position: its box centre in the image is its projection."""

    id: str
    """Identifier used in boxes.json, tracks and reports."""
    position: np.ndarray
    """Centre in world coordinates, metres, shape (3,) float64."""
    name: str | None = None
    """Optional human-readable description."""

    def __post_init__(self) -> None:
        checked_identifier(self.id, "landmark id", SceneError)
        position = np.array(self.position, dtype=np.float64).reshape(-1)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise SceneError(f"landmark {self.id!r}: position must be three finite numbers")
        position.setflags(write=False)
        object.__setattr__(self, "position", position)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Landmark):
            return NotImplemented
        return (
            self.id == other.id
            and self.name == other.name
            and np.array_equal(self.position, other.position)
        )

    def __hash__(self) -> int:
        return hash((self.id, self.name, tuple(self.position)))


@dataclass(frozen=True)
class Scene:
    """Camera intrinsics plus at least four landmarks with distinct ids."""

    camera: CameraIntrinsics
    landmarks: tuple[Landmark, ...]
    description: str = ""
    """Free text kept with the file (where and how the landmarks were surveyed)."""
    _index: dict[str, int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "landmarks", tuple(self.landmarks))
        object.__setattr__(self, "_index", {lm.id: i for i, lm in enumerate(self.landmarks)})

    @property
    def landmark_ids(self) -> tuple[str, ...]:
        """Landmark ids in file order."""
        return tuple(lm.id for lm in self.landmarks)

    def landmark(self, landmark_id: str) -> Landmark:
        """The landmark with this id (SceneError naming the known ids if absent)."""
        try:
            return self.landmarks[self._index[landmark_id]]
        except KeyError:
            known = ", ".join(self.landmark_ids)
            raise SceneError(f"unknown landmark {landmark_id!r} (scene has: {known})") from None

    def object_points(self, ids: Iterable[str] | None = None) -> np.ndarray:
        """Landmark positions as an (n, 3) float64 array, in the order of `ids` (default: all)."""
        chosen = self.landmark_ids if ids is None else tuple(ids)
        if not chosen:
            return np.zeros((0, 3), dtype=np.float64)
        return np.stack([self.landmark(i).position for i in chosen])


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise SceneError(f"{where} must be a finite number, got {value!r}")
    return float(value)


def _require_keys(obj: Any, required: tuple[str, ...], optional: tuple[str, ...], where: str):
    if not isinstance(obj, dict):
        raise SceneError(f"{where} must be a JSON object, got {type(obj).__name__}")
    missing = [k for k in required if k not in obj]
    if missing:
        raise SceneError(f"{where} is missing field(s): {', '.join(missing)}")
    unknown = sorted(set(obj) - set(required) - set(optional))
    if unknown:
        allowed = ", ".join(required + optional)
        raise SceneError(f"{where} has unknown field(s) {', '.join(unknown)} (allowed: {allowed})")


MAX_IMAGE_SIDE = 100_000
"""Largest image width or height a scene may declare (pixels)."""
MAX_DISTORTION = 1e4
"""Largest magnitude of a distortion coefficient (real lenses stay far below)."""


def _check_plausible(values: dict[str, float], distortion: tuple[float, ...]) -> None:
    """Refuse intrinsics no camera has (they would give no valid pose, silently): focal
    lengths outside 1 px..1000x the image size, a principal point far off the image, huge
    distortion coefficients."""
    side = max(values["width"], values["height"])
    for key in ("fx", "fy"):
        if not 1.0 <= values[key] <= 1000.0 * side:
            raise SceneError(f"camera.{key} = {values[key]:g} px is implausible for the image size")
    for key, size in (("cx", values["width"]), ("cy", values["height"])):
        if not -size <= values[key] <= 2.0 * size:
            raise SceneError(f"camera.{key} = {values[key]:g} px lies far outside the image")
    if any(abs(k) > MAX_DISTORTION for k in distortion):
        raise SceneError(f"camera.distortion has a coefficient above {MAX_DISTORTION:g}")


def camera_from_dict(data: Any) -> CameraIntrinsics:
    """Parse and check the `camera` object of a scene file."""
    _require_keys(data, _CAMERA_FIELDS, ("distortion",), "camera")
    values = {k: _number(data[k], f"camera.{k}") for k in _CAMERA_FIELDS}
    distortion_raw = data.get("distortion", [])
    if not isinstance(distortion_raw, list):
        raise SceneError(
            "camera.distortion must be a list of numbers (OpenCV order k1 k2 p1 p2 k3)"
        )
    distortion = tuple(_number(v, "camera.distortion entry") for v in distortion_raw)
    if len(distortion) not in DISTORTION_LENGTHS:
        raise SceneError(
            f"camera.distortion has {len(distortion)} coefficients; OpenCV takes "
            f"{', '.join(map(str, DISTORTION_LENGTHS))}"
        )
    if values["fx"] <= 0 or values["fy"] <= 0:
        raise SceneError("camera.fx and camera.fy must be positive (pixels)")
    for key in ("width", "height"):
        if not 0 < values[key] <= MAX_IMAGE_SIDE or values[key] != int(values[key]):
            raise SceneError(
                f"camera.{key} must be a positive whole number of pixels, at most {MAX_IMAGE_SIDE}"
            )
    _check_plausible(values, distortion)
    return CameraIntrinsics(
        fx=values["fx"],
        fy=values["fy"],
        cx=values["cx"],
        cy=values["cy"],
        distortion=distortion,
        width=int(values["width"]),
        height=int(values["height"]),
    )


def landmark_from_dict(data: Any, position_in_file: int) -> Landmark:
    """Parse and check one entry of the `landmarks` list."""
    where = f"landmarks[{position_in_file}]"
    _require_keys(data, _LANDMARK_FIELDS, ("name",), where)
    landmark_id = data["id"]
    if isinstance(landmark_id, int) and not isinstance(landmark_id, bool):
        landmark_id = str(landmark_id)
    checked_identifier(landmark_id, f"{where}.id", SceneError)
    position = data["position"]
    if not isinstance(position, list) or len(position) != 3:
        raise SceneError(f"{where}.position must be [x, y, z] in metres")
    xyz = [_number(v, f"{where}.position entry") for v in position]
    name = data.get("name")
    if name is not None and not isinstance(name, str):
        raise SceneError(f"{where}.name must be a string")
    return Landmark(id=landmark_id, position=np.array(xyz), name=name)


def scene_from_dict(data: Any) -> Scene:
    """Build a Scene from parsed JSON, raising SceneError on anything a PnP solve cannot use."""
    _require_keys(data, ("camera", "landmarks"), ("description",), "scene")
    camera = camera_from_dict(data["camera"])
    raw_landmarks = data["landmarks"]
    if not isinstance(raw_landmarks, list):
        raise SceneError("scene.landmarks must be a list of {id, position[, name]} objects")
    landmarks = tuple(landmark_from_dict(item, i) for i, item in enumerate(raw_landmarks))
    description = data.get("description", "")
    if not isinstance(description, str):
        raise SceneError("scene.description must be a string")
    scene = Scene(camera=camera, landmarks=landmarks, description=description)
    check_scene(scene)
    return scene


def scene_to_dict(scene: Scene) -> dict[str, Any]:
    """The JSON-ready form of a scene (inverse of scene_from_dict)."""
    cam = scene.camera
    out: dict[str, Any] = {
        "camera": {
            "fx": cam.fx,
            "fy": cam.fy,
            "cx": cam.cx,
            "cy": cam.cy,
            "distortion": list(cam.distortion),
            "width": cam.width,
            "height": cam.height,
        },
        "landmarks": [],
    }
    for lm in scene.landmarks:
        entry: dict[str, Any] = {"id": lm.id, "position": [float(v) for v in lm.position]}
        if lm.name is not None:
            entry["name"] = lm.name
        out["landmarks"].append(entry)
    if scene.description:
        out["description"] = scene.description
    return out


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene JSON file (SceneError with the file name on any problem)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise SceneError(f"cannot read scene file {path}: {error.strerror or error}") from None
    except UnicodeDecodeError:  # an image or other binary file picked by mistake
        raise SceneError(f"scene file {path} is not a JSON text file") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise SceneError(
            f"scene file {path} is not valid JSON (line {error.lineno}: {error.msg})"
        ) from None
    try:
        return scene_from_dict(data)
    except SceneError as error:
        raise SceneError(f"scene file {path}: {error}") from None


def save_scene(scene: Scene, path: str | Path) -> None:
    """Write a scene as JSON, one line for the camera and one per landmark."""
    data = scene_to_dict(scene)

    def compact(value: Any) -> str:
        # Round away binary noise (480.84999999999997) far below any pixel or metre precision.
        if isinstance(value, float):
            return json.dumps(round(value, 9))
        if isinstance(value, list):
            return "[" + ", ".join(compact(v) for v in value) + "]"
        if isinstance(value, dict):
            return "{" + ", ".join(f"{json.dumps(k)}: {compact(v)}" for k, v in value.items()) + "}"
        return json.dumps(value)

    lines = ["{", f'  "camera": {compact(data["camera"])},', '  "landmarks": [']
    lines.append(",\n".join(f"    {compact(entry)}" for entry in data["landmarks"]))
    lines.append("  ]" + ("," if "description" in data else ""))
    if "description" in data:
        lines.append(f'  "description": {json.dumps(data["description"])}')
    lines.append("}")
    write_text(path, "\n".join(lines) + "\n")


def check_scene(scene: Scene, *, tolerance_m: float = 0.01) -> None:
    """Raise SceneError when the landmarks cannot give a pose.

    Errors: fewer than four landmarks, duplicate ids, two landmarks closer than `tolerance_m`,
    or all landmarks on one line (rotation about that line is then unobservable).
    """
    ids = scene.landmark_ids
    if len(ids) < MIN_LANDMARKS:
        raise SceneError(
            f"the scene has {len(ids)} landmark(s); localisation needs at least {MIN_LANDMARKS}"
        )
    duplicates = sorted(i for i, count in Counter(ids).items() if count > 1)
    if duplicates:
        raise SceneError(f"duplicate landmark id(s): {', '.join(duplicates)}")
    points = scene.object_points()
    distances = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
    too_close = np.argwhere(np.triu(distances < tolerance_m, k=1))
    if too_close.size:
        a, b = too_close[0]  # the first pair in (a, b) order, as a pairwise loop would find
        raise SceneError(
            f"landmarks {ids[a]} and {ids[b]} are less than {tolerance_m * 100:.0f} cm apart"
        )
    if _off_line_distance(points) < tolerance_m:
        raise SceneError("all landmarks lie on one line: the camera pose cannot be recovered")


def scene_warnings(
    scene: Scene,
    *,
    tolerance_m: float = 0.01,
    flatness_ratio: float = 0.03,
    symmetry_tolerance: float = 0.02,
) -> list[str]:
    """Layout problems that do not stop localisation but weaken it, as readable sentences.

    - three landmarks (nearly) on one line: P3P on that triple is degenerate;
    - all landmarks (nearly) on one plane (off-plane spread below `flatness_ratio` of the
      layout's size, or below `tolerance_m`): fine for a known assignment, but the pose has a
      two-fold ambiguity at some viewpoints;
    - a symmetric layout (some relabelling keeps every pairwise distance within
      `symmetry_tolerance` of the layout's size): the correspondence search cannot tell the
      landmarks apart (the paper asks for a non-symmetric configuration).
    """
    check_scene(scene, tolerance_m=tolerance_m)
    ids = scene.landmark_ids
    points = scene.object_points()
    warnings: list[str] = []
    size = float(np.linalg.norm(points - points.mean(axis=0), axis=1).max())
    for triple in collinear_triples(points, max(tolerance_m, flatness_ratio * size)):
        names = ", ".join(ids[i] for i in triple)
        warnings.append(f"landmarks {names} are (nearly) collinear: avoid relying on them alone")
    if _off_plane_distance(points) < max(tolerance_m, flatness_ratio * size):
        warnings.append(
            "all landmarks are (nearly) coplanar: poses can flip between two solutions at "
            "some viewpoints; place one landmark out of the plane if you can"
        )
    if len(ids) <= 6:
        distances = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
        identity = tuple(range(len(ids)))
        for perm in itertools.permutations(range(len(ids))):
            if perm == identity:
                continue
            permuted = distances[np.ix_(perm, perm)]
            if np.abs(permuted - distances).max() <= symmetry_tolerance * distances.max():
                swapped = ", ".join(f"{ids[i]}<->{ids[p]}" for i, p in enumerate(perm) if i < p)
                warnings.append(
                    f"the layout is (nearly) symmetric ({swapped} keeps every distance): the "
                    "correspondence search cannot tell these landmarks apart"
                )
                break
    return warnings


def collinear_triples(points: np.ndarray, spread_m: float) -> list[tuple[int, int, int]]:
    """Index triples (i < j < k, in lexicographic order) whose off-line spread
    (`_off_line_distance`) is below `spread_m`.

    One pass per first index i: the spread of every (j, k) follows in closed form from the
    Gram matrix of the offsets p_j - p_i (one matrix product), so the work per pass is an
    (n, n) array instead of one SVD per triple. For three points the centred scatter has
    trace T = (|ij|^2 + |ik|^2 + |jk|^2) / 3 and product of its two eigenvalues
    P = |(p_j - p_i) x (p_k - p_i)|^2 / 3; the spread is the root of the smaller eigenvalue,
    2P / (T + sqrt(T^2 - 4P)). Candidates within a relative 1e-6 of the threshold are
    confirmed with the SVD, so the verdicts are the SVD's.
    """
    points = np.asarray(points, dtype=np.float64)
    count = len(points)
    margin = spread_m * (1.0 + 1e-6) + 1e-12
    found: list[tuple[int, int, int]] = []
    for i in range(count - 2):
        offsets = points[i + 1 :] - points[i]
        gram = offsets @ offsets.T
        squared = np.diag(gram)
        cross_squared = np.maximum(np.outer(squared, squared) - gram * gram, 0.0)
        trace = 2.0 * (squared[:, None] + squared[None, :] - gram) / 3.0
        product = cross_squared / 3.0
        root = np.sqrt(np.maximum(trace * trace - 4.0 * product, 0.0))
        denominator = trace + root
        smaller = np.divide(
            2.0 * product, denominator, out=np.zeros_like(product), where=denominator > 0
        )
        js, ks = np.nonzero(np.triu(np.sqrt(smaller) < margin, k=1))
        if js.size == 0:
            continue
        triples = np.stack([np.full_like(js, i), js + i + 1, ks + i + 1], axis=1)
        corners = points[triples]
        centred = corners - corners.mean(axis=1, keepdims=True)
        spreads = np.linalg.svd(centred, compute_uv=False)[:, 1]
        found.extend(tuple(int(v) for v in t) for t in triples[spreads < spread_m])
    return found


def _off_line_distance(points: np.ndarray) -> float:
    """Spread of the points off their best-fit line (metres): 2nd singular value, centred."""
    centred = points - points.mean(axis=0)
    singular = np.linalg.svd(centred, compute_uv=False)
    return float(singular[1]) if singular.size > 1 else 0.0


def _off_plane_distance(points: np.ndarray) -> float:
    """Spread of the points off their best-fit plane (metres): 3rd singular value, centred."""
    centred = points - points.mean(axis=0)
    singular = np.linalg.svd(centred, compute_uv=False)
    return float(singular[2]) if singular.size > 2 else 0.0
