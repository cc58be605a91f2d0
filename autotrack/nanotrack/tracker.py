"""NanoTrack V2 (a MobileNetV3 + BAN Siamese tracker) with AutoTrack's call shape and signals.

The networks are the two ONNX files OpenCV's `cv2.TrackerNano` loads (shipped in `models/`,
Apache-2.0, see `models/SOURCE.txt`), run with `cv2.dnn` exactly as `cv2.TrackerNano` runs them
(OpenCV's modules/video/src/tracking/tracker_nano.cpp: the same crops, cosine window, size and
ratio penalties, box decoding and learning rate; tests/test_nanotrack.py checks the boxes
against `cv2.TrackerNano_create` on real frames). The loop is ours, not `cv2.TrackerNano`'s,
for two reasons: `cv2.TrackerNano` returns only the best score, not the score map a
`TrackResult` carries (running the head a second time on the same crop would double the cost),
and it cannot be moved to a box without re-extracting its template (`init`), which the hybrid
tracker must do to re-place a lost Siamese track while keeping the first frame's clean template.

The score map is a response map: its local and global variation are computed with the same
functions as AutoTrack's (paper eq. 2 and the release's eta), and the frame is flagged
aberrant by the same rule, eta >= phi. NanoTrack learns nothing online, so the flag only
reports; the hybrid tracker reads it.

Two quirks of `cv2.TrackerNano` are kept so that the boxes are its boxes: the search region is
twice the exemplar context (C++ integer division 255 / 127), and the scale penalty divides by
the size function of the target's position instead of its size.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from autotrack.errors import InputError
from autotrack.result import TrackResult
from autotrack.tracker import regularization

MODELS = Path(__file__).resolve().parent / "models"
BACKBONE = MODELS / "nanotrack_backbone_sim.onnx"
"""The shared MobileNetV3 backbone (template and search crops)."""
HEAD = MODELS / "nanotrack_head_sim.onnx"
"""The BAN neck and head: inputs input1 (template features), input2 (search features)."""

EXEMPLAR_SIZE = 127
"""Side of the template crop fed to the backbone (pixels)."""
INSTANCE_SIZE = 255
"""Side of the search crop fed to the backbone (pixels)."""
TOTAL_STRIDE = 16
"""Pixels of the search crop per cell of the score map."""
SCORE_SIZE = (INSTANCE_SIZE - EXEMPLAR_SIZE) // TOTAL_STRIDE + 8
"""Side of the score map (16 cells), as cv2.TrackerNano sizes it."""
MIN_SIDE = 10.0
"""cv2.TrackerNano never lets a box side fall below 10 pixels."""


@dataclass(frozen=True)
class NanoTrackParams:
    """NanoTrack's tracking constants (cv2.TrackerNano's `trackerConfig`) and the models."""

    backbone_path: Path = BACKBONE
    """ONNX backbone file."""
    head_path: Path = HEAD
    """ONNX neck + head file."""
    window_influence: float = 0.455
    """Weight of the cosine window against the penalised score (cv2.TrackerNano)."""
    learning_rate: float = 0.37
    """Rate the box size follows the prediction, times the best score (cv2.TrackerNano)."""
    penalty_k: float = 0.055
    """Strength of the size and aspect-ratio change penalty (cv2.TrackerNano)."""
    context_amount: float = 0.5
    """Context added around the target, as a fraction of (w + h) (cv2.TrackerNano)."""
    phi: float = 0.3
    """Aberrance threshold on the score map's global variation eta: AutoTrack's phi."""


def load_networks(params: NanoTrackParams) -> tuple[cv2.dnn.Net, cv2.dnn.Net]:
    """(backbone, head) networks; InputError with a one-line reason when a file is missing or
    is not a network OpenCV can read."""
    networks = []
    for path in (Path(params.backbone_path), Path(params.head_path)):
        if not path.is_file():
            raise InputError(f"NanoTrack model not found: {path}")
        try:
            network = cv2.dnn.readNet(str(path))
        except cv2.error as error:
            reason = str(error).strip().splitlines()[-1]
            raise InputError(f"NanoTrack model {path} cannot be loaded: {reason}") from None
        if network.empty():
            raise InputError(f"NanoTrack model {path} cannot be loaded: empty network")
        networks.append(network)
    return networks[0], networks[1]


def context_side(width: float, height: float, context_amount: float) -> float:
    """Side of the square context around a (width, height) target (SiamFC's crop rule)."""
    pad = context_amount * (width + height)
    return math.sqrt((width + pad) * (height + pad))


def size_measure(width: np.ndarray, height: np.ndarray) -> np.ndarray:
    """SiamRPN's size of a box with its context: sqrt((w + p)(h + p)), p = (w + h) / 2."""
    pad = (width + height) * 0.5
    return np.sqrt((width + pad) * (height + pad))


def crop_square(
    image: np.ndarray, centre: tuple[float, float], side: int, out_side: int
) -> np.ndarray:
    """The `side`-pixel square at `centre` resized to `out_side`, padded with the image's mean
    colour where it leaves the image (cv2.TrackerNano's getSubwindow, padding only the crop)."""
    half = (side + 1) // 2
    x0, y0 = int(centre[0]) - half, int(centre[1]) - half
    height, width = image.shape[:2]
    inside = image[max(y0, 0) : max(y0 + side, 0), max(x0, 0) : max(x0 + side, 0)]
    top, left = max(-y0, 0), max(-x0, 0)
    bottom = max(y0 + side - height, 0)
    right = max(x0 + side - width, 0)
    if top or left or bottom or right:
        mean_colour = cv2.mean(image)
        if inside.size == 0:  # the whole square is off the image
            patch = np.full((side, side, 3), mean_colour[:3]).astype(image.dtype)
        else:
            patch = cv2.copyMakeBorder(
                inside, top, bottom, left, right, cv2.BORDER_CONSTANT, value=mean_colour
            )
    else:
        patch = inside
    return cv2.resize(patch, (out_side, out_side))


def foreground_at(result: TrackResult, point: tuple[float, float]) -> float:
    """NanoTrack's foreground probability at an image point (x, y): its score map read through
    the geometry of the search crop the map came from (`result.search_box`: the square resized
    to INSTANCE_SIZE; cell (row, col) looks at crop pixel (col - 8, row - 8) x TOTAL_STRIDE +
    INSTANCE_SIZE // 2), bilinear between cells; 0 outside the cells, where the network did not
    look, and NaN on a result without a map (the first frame)."""
    if result.response_map is None:
        return math.nan
    left, top, side, _ = result.search_box
    per_pixel = INSTANCE_SIZE / side  # crop pixels per image pixel
    cells = [
        ((coordinate - origin) * per_pixel - INSTANCE_SIZE // 2) / TOTAL_STRIDE + SCORE_SIZE // 2
        for coordinate, origin in ((point[1], top), (point[0], left))
    ]
    if not all(0.0 <= cell <= SCORE_SIZE - 1 for cell in cells):
        return 0.0
    row, col = cells
    return float(cv2.getRectSubPix(result.response_map, (1, 1), (col, row))[0, 0])


class NanoTrack:
    """NanoTrack V2 on RGB (or grey) uint8 frames: `init(frame, box)`, `update(frame)`, each
    returning a `TrackResult` whose response map is the 16x16 foreground score map."""

    def __init__(self, params: NanoTrackParams | None = None) -> None:
        self.params = params or NanoTrackParams()
        self._backbone, self._head = load_networks(self.params)
        self._window = cv2.createHanningWindow((SCORE_SIZE, SCORE_SIZE), cv2.CV_32F)
        offsets = (np.arange(SCORE_SIZE, dtype=np.float32) - SCORE_SIZE // 2) * TOTAL_STRIDE
        self._grid_x = np.tile(offsets + INSTANCE_SIZE // 2, (SCORE_SIZE, 1))
        self._grid_y = self._grid_x.T.copy()
        self.position = np.zeros(2)
        """Target centre (x, y), 0-based pixels."""
        self.size = np.zeros(2)
        """Target (w, h), pixels."""
        self._first_size = np.ones(2)
        self._frame_shape: tuple[int, int] | None = None
        self._previous: tuple[np.ndarray, tuple[float, float]] | None = None
        self.frame_number = 0
        self.peak_cell: tuple[int, int] | None = None
        """(row, col) of the score-map cell the last box came from (the penalised maximum)."""

    @staticmethod
    def _rgb(frame: np.ndarray) -> np.ndarray:
        if frame.ndim == 2:
            return cv2.cvtColor(frame, cv2.COLOR_GRAY2RGB)
        return frame

    def _features(self, crop: np.ndarray) -> np.ndarray:
        # The frames are RGB already: no swap (cv2.TrackerNano swaps its BGR input to RGB).
        self._backbone.setInput(cv2.dnn.blobFromImage(crop, 1.0, swapRB=False))
        return self._backbone.forward()

    def init(self, frame_rgb: np.ndarray, box: Sequence[float]) -> TrackResult:
        """Start on `frame_rgb` from a 0-based (x, y, w, h) box: extracts the template."""
        image = self._rgb(frame_rgb)
        x, y, w, h = (float(v) for v in box)
        if not (w > 0 and h > 0):
            raise InputError(f"NanoTrack: the box {tuple(box)} has no area")
        self._frame_shape = image.shape[:2]
        self.position = np.array([x + w / 2.0, y + h / 2.0])
        self.size = np.array([w, h])
        self._first_size = self.size.copy()
        side = int(context_side(w, h, self.params.context_amount))
        template = self._features(crop_square(image, tuple(self.position), side, EXEMPLAR_SIZE))
        self._head.setInput(template, "input1")
        self._previous = None
        self.frame_number = 1
        return self._result(math.nan, None, None, math.nan, False, self.position, side)

    def place(self, box: Sequence[float]) -> None:
        """Move the track to a 0-based (x, y, w, h) box, keeping the first frame's template
        (the hybrid tracker re-places a lost Siamese track where the trusted one is)."""
        x, y, w, h = (float(v) for v in box)
        self.position = np.array([x + w / 2.0, y + h / 2.0])
        self.size = np.array([max(w, MIN_SIDE), max(h, MIN_SIDE)])
        self._previous = None  # the next map is of another place: no variation across the jump

    def update(self, frame_rgb: np.ndarray) -> TrackResult:
        """Track into the next frame; returns the box, the score map and its variations."""
        if self._frame_shape is None:
            raise InputError("NanoTrack: update() called before init()")
        image = self._rgb(frame_rgb)
        if image.shape[:2] != self._frame_shape:
            raise InputError(
                f"NanoTrack: frame of {image.shape[1]}x{image.shape[0]} after frames of "
                f"{self._frame_shape[1]}x{self._frame_shape[0]}"
            )
        p = self.params
        width, height = self.size
        context = float(int(width + height)) * p.context_amount
        side = math.sqrt((width + context) * (height + context))
        scale_z = EXEMPLAR_SIZE / side
        search_side = int(side * (INSTANCE_SIZE // EXEMPLAR_SIZE))
        centre = self.position.copy()
        crop = crop_square(image, tuple(centre), search_side, INSTANCE_SIZE)
        self._head.setInput(self._features(crop), "input2")
        logits, offsets = self._head.forward(["output1", "output2"])
        logits = logits.reshape(2, SCORE_SIZE, SCORE_SIZE)
        score = 1.0 / (1.0 + np.exp(logits[0] - logits[1]))  # the two-class softmax
        box_x1 = self._grid_x - offsets[0, 0]
        box_y1 = self._grid_y - offsets[0, 1]
        box_w = self._grid_x + offsets[0, 2] - box_x1
        box_h = self._grid_y + offsets[0, 3] - box_y1
        penalty = self._penalty(box_w, box_h, width / height)
        penalised = penalty * score * (1.0 - p.window_influence) + self._window * p.window_influence
        row, col = np.unravel_index(int(np.argmax(penalised)), penalised.shape)
        rate = float(penalty[row, col] * score[row, col]) * p.learning_rate
        cx = box_x1[row, col] + box_w[row, col] / 2.0
        cy = box_y1[row, col] + box_h[row, col] / 2.0
        frame_h, frame_w = self._frame_shape
        new_x = min(max(centre[0] + (cx - INSTANCE_SIZE // 2) / scale_z, 0.0), frame_w)
        new_y = min(max(centre[1] + (cy - INSTANCE_SIZE // 2) / scale_z, 0.0), frame_h)
        new_w = box_w[row, col] / scale_z * rate + (1.0 - rate) * width
        new_h = box_h[row, col] / scale_z * rate + (1.0 - rate) * height
        self.position = np.array([new_x, new_y])
        self.size = np.array(
            [min(max(new_w, MIN_SIDE), frame_w), min(max(new_h, MIN_SIDE), frame_h)]
        )
        self.frame_number += 1
        self.peak_cell = (int(row), int(col))
        response = score.astype(np.float32)
        displacement = (float(row - SCORE_SIZE // 2), float(col - SCORE_SIZE // 2))
        variation, eta = self._variation(response, displacement)
        aberrant = bool(np.isfinite(eta)) and regularization.is_aberrant(eta, p.phi)
        peak = float(penalised[row, col])
        return self._result(peak, response, variation, eta, aberrant, centre, search_side)

    def _penalty(self, box_w: np.ndarray, box_h: np.ndarray, ratio: float) -> np.ndarray:
        """exp(-k (r c - 1)): r the aspect change, c the size change (cv2.TrackerNano's, whose
        size reference is the size function of the target's position)."""
        size_change = size_measure(box_w, box_h) / size_measure(*self.position.astype(np.float32))
        size_change = np.maximum(size_change, 1.0 / size_change)
        ratio_change = ratio / (box_w / box_h)
        ratio_change = np.maximum(ratio_change, 1.0 / ratio_change)
        return np.exp(-(ratio_change * size_change - 1.0) * self.params.penalty_k)

    def _variation(
        self, response: np.ndarray, displacement: tuple[float, float]
    ) -> tuple[np.ndarray | None, float]:
        """Local variation (eq. 2) and eta of the score map against the previous frame's."""
        previous, self._previous = self._previous, (response, displacement)
        if previous is None:
            return None, math.nan
        variation = regularization.local_variation(response, displacement, *previous)
        return variation, regularization.global_variation(variation)

    def _result(self, peak, response, variation, eta, aberrant, centre, search_side):
        width, height = self.size
        half = (search_side + 1) // 2
        search_box = (
            float(int(centre[0]) - half),
            float(int(centre[1]) - half),
            float(search_side),
            float(search_side),
        )
        return TrackResult(
            frame_index=self.frame_number - 1,
            box=(
                float(self.position[0] - width / 2.0),
                float(self.position[1] - height / 2.0),
                float(width),
                float(height),
            ),
            peak_score=peak,
            response_map=response,
            local_variation=variation,
            global_variation=eta,
            theta_ref=math.nan,
            theta=math.nan,
            aberrant=aberrant,
            scale_factor=math.sqrt(width * height / float(np.prod(self._first_size))),
            search_box=search_box,
        )
