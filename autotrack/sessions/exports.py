"""A session's tracks and poses written out: OTB track files, one CSV, TUM poses, and the
formats other tools read: MOT Challenge (`autotrack.io.mot`), CVAT for video 1.1
(`autotrack.io.cvat`) and the evo command that scores the TUM poses."""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np

from autotrack.errors import InputError, SessionError
from autotrack.io.csv_table import write_csv
from autotrack.io.cvat import write_cvat_video
from autotrack.io.frames import open_frames
from autotrack.io.mot import write_mot
from autotrack.io.otb_boxes import write_boxes
from autotrack.io.tum import write_tum
from autotrack.sessions.names import safe_file_name
from autotrack.sessions.session import Session


def target_label(session: Session, target_id: str) -> str:
    """How the exports name a target: its id, with the landmark it localises beside it
    ("T1 (A)"), or the id alone."""
    landmark = session.landmark_ids.get(target_id)
    return target_id if landmark is None else f"{target_id} ({landmark})"


def track_file_name(session: Session, target_id: str) -> str:
    """The OTB track file of a target: `T1.txt`, or `T1_A.txt` for a target that localises
    landmark A (the landmark reduced to letters, digits, '_', '.' and '-')."""
    landmark = session.landmark_ids.get(target_id)
    stem = target_id if landmark is None else safe_file_name(f"{target_id}_{landmark}")
    return f"{stem}.txt"


def write_otb_tracks(
    session: Session, directory: str | Path, *, overwrite: bool = False
) -> list[Path]:
    """One `<target>.txt` per target (`<target>_<landmark>.txt` for a target that localises a
    landmark, `track_file_name`) in the benchmark format (autotrack.io.otb_boxes.write_boxes):
    a line `x,y,w,h` per frame 0..last, 1-BASED x and y, `NaN` where the target has no box.
    Targets the user deleted are not written."""
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise SessionError(f"cannot create {directory}: {error}") from error
    targets = session.exported_targets
    paths = [directory / track_file_name(session, target_id) for target_id in targets]
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
    """Combined CSV: frame (0-based), target, landmark (the one it localises, else empty), x, y,
    w, h (0-based pixels), score, aberrant (0/1), trusted (the hybrid's `both`, `filter` or
    `siamese`, else empty); one row per frame and target with a box, ordered by frame then
    target."""
    rows = []
    targets = session.exported_targets
    for frame_index in session.frame_indices.tolist():
        for target_id in targets:
            box = session.tracks[target_id][frame_index]
            if not np.isfinite(box).all():
                continue
            score = float(session.scores[target_id][frame_index])
            flag = int(session.aberrant[target_id][frame_index])
            landmark = session.landmark_ids.get(target_id) or ""
            trusted = session.trusted.get(target_id)
            choice = "" if trusted is None else str(trusted[frame_index])
            rows.append(
                [frame_index, target_id, landmark, *(float(v) for v in box), score, flag, choice]
            )
    header = ["frame", "target", "landmark", "x", "y", "w", "h", "score", "aberrant", "trusted"]
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


KEYFRAME_EVENTS = frozenset({"box_drawn", "box_corrected"})
"""Session event kinds that mark a frame the user set by hand (a CVAT keyframe)."""

GROUND_TRUTH_POSES_FILE = "poses_gt.tum"
"""The ground-truth trajectory beside a synthetic sequence (`autotrack synth`)."""


def session_keyframes(session: Session) -> dict[str, set[int]]:
    """Target id -> frames where the user drew or corrected its box."""
    keyframes: dict[str, set[int]] = {}
    for event in session.events:
        if event.kind in KEYFRAME_EVENTS and event.target_id:
            keyframes.setdefault(event.target_id, set()).add(int(event.frame_index))
    return keyframes


def session_frame_size(session: Session) -> tuple[int, int] | None:
    """(width, height) of the session's source frames, or None when the source is not readable
    here (then CVAT's <original_size> is left out)."""
    source = session.source
    if not source:
        return None
    try:
        with open_frames(source) as frames:
            return frames.frame_size
    except (InputError, OSError):
        return None


def _refuse_existing(path: Path, overwrite: bool) -> None:
    if path.exists() and not overwrite:
        raise SessionError(f"{path} already exists; not replaced (--force / overwrite=True does)")


def export_session_mot(session: Session, path: str | Path, *, overwrite: bool = False) -> dict:
    """The session's tracks (deleted targets left out) as a MOT Challenge file; returns each
    target's label (`target_label`: its id, and the landmark it localises) -> MOT id."""
    path = Path(path)
    _refuse_existing(path, overwrite)
    labels = {target_label(session, t): t for t in session.exported_targets}
    try:
        return write_mot(
            path,
            {label: session.tracks[t] for label, t in labels.items()},
            {label: session.scores[t] for label, t in labels.items()},
        )
    except OSError as error:
        raise SessionError(f"cannot write {path}: {error}") from error


def export_session_cvat(
    session: Session,
    path: str | Path,
    *,
    overwrite: bool = False,
    all_keyframes: bool = False,
    frame_size: tuple[int, int] | None = None,
) -> Path:
    """The session's tracks as CVAT for video 1.1 XML, each labelled `target_label` (its id and
    the landmark it localises), the user's drawn and corrected frames as keyframes (every box
    with `all_keyframes`).

    `frame_size` (width, height) defaults to the size of the session's source frames; CVAT's
    readers need it (<original_size>), so SessionError when neither is available.
    """
    path = Path(path)
    _refuse_existing(path, overwrite)
    frame_size = frame_size or session_frame_size(session)
    source = session.source or session.path.stem
    if frame_size is None:
        raise SessionError(
            f"the session's source {source} cannot be read here to get the frame size CVAT "
            "needs: give --frame-size WIDTHxHEIGHT"
        )
    labels = {target_label(session, t): t for t in session.exported_targets}
    keyframes = session_keyframes(session)
    try:
        return write_cvat_video(
            path,
            {label: session.tracks[t] for label, t in labels.items()},
            keyframes={label: keyframes.get(t, set()) for label, t in labels.items()},
            all_keyframes=all_keyframes,
            frame_size=frame_size,
            task_name=Path(source).name or source,
        )
    except OSError as error:
        raise SessionError(f"cannot write {path}: {error}") from error


def evo_ape_command(session: Session, poses: str | Path, ground_truth: str | Path | None) -> str:
    """The evo command computing the absolute position error of the exported poses against the
    ground truth (no alignment: both trajectories are in the scene's world frame, metres).

    The ground truth defaults to poses_gt.tum beside the session's source; SessionError when
    there is none.
    """
    if ground_truth is None:
        source = session.source
        candidate = Path(source) / GROUND_TRUTH_POSES_FILE if source else None
        if candidate is None or not candidate.is_file():
            raise SessionError(
                f"--evo needs the ground-truth trajectory: give --gt FILE (no "
                f"{GROUND_TRUTH_POSES_FILE} in the session's source {source})"
            )
        ground_truth = candidate
    return shlex.join(
        ["evo_ape", "tum", str(ground_truth), str(poses), "--pose_relation", "trans_part", "-v"]
    )
