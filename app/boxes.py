"""Boxes as the user types and reads them, and the ground truth found beside a sequence."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from autotrack.errors import InputError
from autotrack.evaluation.metrics import overlaps
from autotrack.io.tum import read_tum
from autotrack.pipeline import TrackedTarget

Box = tuple[float, float, float, float]

OVERLAP_CORRECTS = 0.5
"""A new box overlapping a target's box on the frame by more than this IoU corrects that target
instead of stacking a new one on it."""


def parse_box(text: str) -> Box:
    """'x, y, w, h' (0-based pixels) typed by the user."""
    parts = [part for part in text.replace(";", ",").replace(" ", ",").split(",") if part]
    try:
        values = [float(part) for part in parts]
    except ValueError:
        raise InputError(f"type the box as four numbers 'x, y, w, h', not {text!r}") from None
    if len(values) != 4 or not all(math.isfinite(value) for value in values):
        raise InputError(f"type the box as four numbers 'x, y, w, h', not {text!r}")
    return (values[0], values[1], values[2], values[3])


def format_box(box: Box) -> str:
    """A box as the text field shows it."""
    return ", ".join(f"{value:.1f}" for value in box)


def ground_truth_positions(scene_path: Path | None) -> np.ndarray | None:
    """Camera positions of the `poses_gt.tum` beside a scene file, if there is one."""
    if scene_path is None:
        return None
    tum = scene_path.parent / "poses_gt.tum"
    if not tum.is_file():
        return None
    _stamps, positions, _quaternions = read_tum(tum)
    return positions


def overlapped_target(targets: list[TrackedTarget], frame_index: int, box: Box) -> str | None:
    """The target whose box on `frame_index` the new `box` overlaps most, if by more than
    OVERLAP_CORRECTS (IoU)."""
    shown = [t for t in targets if frame_index in t.results]
    if not shown:
        return None
    boxes = np.array([t.results[frame_index].box for t in shown])
    ious = overlaps(np.repeat(np.array([box]), len(shown), axis=0), boxes)
    best = int(np.argmax(ious))
    return shown[best].id if ious[best] > OVERLAP_CORRECTS else None
