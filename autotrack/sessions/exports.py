"""A session's tracks and poses written out: OTB track files, one CSV, TUM poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from autotrack.errors import SessionError
from autotrack.io.csv_table import write_csv
from autotrack.io.otb_boxes import write_boxes
from autotrack.io.tum import write_tum
from autotrack.sessions.session import Session


def write_otb_tracks(
    session: Session, directory: str | Path, *, overwrite: bool = False
) -> list[Path]:
    """One `<target>.txt` per target in the benchmark format (autotrack.datasets.write_boxes):
    a line `x,y,w,h` per frame 0..last, 1-BASED x and y, `NaN` where the target has no box.
    Targets the user deleted are not written."""
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise SessionError(f"cannot create {directory}: {error}") from error
    targets = session.exported_targets
    paths = [directory / f"{target_id}.txt" for target_id in targets]
    taken = [str(path) for path in paths if path.exists()]
    if taken and not overwrite:
        raise SessionError(
            f"{', '.join(taken)} already exist(s); not replaced (--force / overwrite=True "
            "replaces them)"
        )
    for target_id, path in zip(targets, paths, strict=True):
        try:
            write_boxes(path, session.tracks[target_id])
        except OSError as error:
            raise SessionError(f"cannot write {path}: {error}") from error
    return paths


def write_tracks_csv(session: Session, path: str | Path, *, overwrite: bool = False) -> Path:
    """Combined CSV: frame (0-based), target, x, y, w, h (0-based pixels), score, aberrant (0/1);
    one row per frame and target with a box, ordered by frame then target."""
    rows = []
    targets = session.exported_targets
    for frame_index in session.frame_indices.tolist():
        for target_id in targets:
            box = session.tracks[target_id][frame_index]
            if not np.isfinite(box).all():
                continue
            score = float(session.scores[target_id][frame_index])
            flag = int(session.aberrant[target_id][frame_index])
            rows.append([frame_index, target_id, *(float(v) for v in box), score, flag])
    header = ["frame", "target", "x", "y", "w", "h", "score", "aberrant"]
    try:
        return write_csv(path, header, rows, overwrite=overwrite)
    except FileExistsError as error:
        raise SessionError(
            f"{path} already exists; not replaced (--force / overwrite=True replaces it)"
        ) from error
    except OSError as error:
        raise SessionError(f"cannot write {path}: {error}") from error


def write_tum_poses(session: Session, path: str | Path, *, overwrite: bool = False) -> int:
    """The session's valid camera poses as a TUM file (for evo); timestamp = frame index / fps.

    Returns the number of poses written.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise SessionError(
            f"{path} already exists; not replaced (--force / overwrite=True replaces it)"
        )
    poses = session.poses
    keep = poses.valid
    try:
        return write_tum(
            path,
            poses.frame_indices[keep] / session.fps,
            poses.positions[keep],
            poses.quaternions_xyzw[keep],
        )
    except OSError as error:
        raise SessionError(f"cannot write {path}: {error}") from error
