"""MOT Challenge text files (the tracker-output layout of the MOT benchmarks and py-motmetrics),
written and read back.

One line per frame and target, ``frame,id,bb_left,bb_top,bb_width,bb_height,conf,-1,-1,-1``;
frames count from 1 and the box corner is 1-based, as in the benchmarks' own files (and our
OTB-style box files); ids are integers from 1 in target order. Tracks are target id -> (N, 4)
array of 0-based x, y, w, h boxes, row i = frame i, NaN rows where the target has no box (what
`autotrack.sessions.Session.tracks` holds).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from autotrack.errors import InputError
from autotrack.io.atomic import write_text


def visible_rows(boxes: np.ndarray) -> np.ndarray:
    """Per row: a finite box with positive width and height."""
    return np.isfinite(boxes).all(axis=1) & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)


def track_boxes(target_id: str, boxes: np.ndarray) -> np.ndarray:
    """`boxes` as an (N, 4) float64 array; InputError naming the track otherwise."""
    array = np.asarray(boxes, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 4:
        raise InputError(f"track {target_id}: boxes must be N x 4, got shape {array.shape}")
    return array


def write_mot(
    path: str | Path,
    tracks: Mapping[str, np.ndarray],
    scores: Mapping[str, np.ndarray] | None = None,
) -> dict[str, int]:
    """Write the tracks as a MOT Challenge result file; returns target id -> MOT id.

    `conf` is the target's peak response score for the frame when `scores` has it, else 1.
    """
    ids = {target_id: number for number, target_id in enumerate(tracks, start=1)}
    rows: list[tuple[int, int, str]] = []
    for target_id, number in ids.items():
        boxes = track_boxes(target_id, tracks[target_id])
        target_scores = None if scores is None else scores.get(target_id)
        for frame_index in np.flatnonzero(visible_rows(boxes)):
            x, y, w, h = boxes[frame_index]
            conf = 1.0
            if target_scores is not None and np.isfinite(target_scores[frame_index]):
                conf = float(target_scores[frame_index])
            text = f"{frame_index + 1},{number},{x + 1:.2f},{y + 1:.2f},{w:.2f},{h:.2f},{conf:.4f}"
            rows.append((int(frame_index), number, text + ",-1,-1,-1"))
    rows.sort()
    write_text(path, "".join(f"{text}\n" for _, _, text in rows))
    return ids


def read_mot(path: str | Path, frame_count: int | None = None) -> dict[int, np.ndarray]:
    """Read a MOT Challenge file (results or ground truth): MOT id -> (N, 4) 0-based boxes, row
    i = frame i (0-based), NaN where the id has no box. N is `frame_count` or the last frame."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise InputError(f"cannot read MOT file {path}: {error.strerror}") from error
    entries: list[tuple[int, int, tuple[float, float, float, float]]] = []
    for line_number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        fields = [field.strip() for field in line.split(",")]
        try:
            frame, number = int(float(fields[0])), int(float(fields[1]))
            x, y, w, h = (float(value) for value in fields[2:6])
        except (ValueError, IndexError):
            raise InputError(
                f"{path}, line {line_number}: expected frame,id,left,top,width,height,..."
            ) from None
        if frame < 1:
            raise InputError(f"{path}, line {line_number}: frames count from 1, got {frame}")
        entries.append((frame - 1, number, (x - 1.0, y - 1.0, w, h)))
    last = max((frame for frame, _, _ in entries), default=-1)
    count = frame_count if frame_count is not None else last + 1
    if last >= count:
        raise InputError(f"{path}: frame {last + 1} is past the {count} frames of the video")
    tracks: dict[int, np.ndarray] = {}
    for frame, number, box in entries:
        tracks.setdefault(number, np.full((count, 4), np.nan))[frame] = box
    return dict(sorted(tracks.items()))
