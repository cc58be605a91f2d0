"""Files offered for download, built from a session recording by the library's exporters."""

from __future__ import annotations

import contextlib
import os
import tempfile
import zipfile
from collections.abc import Callable
from io import BytesIO
from pathlib import Path

from autotrack.errors import AutoTrackError, InputError
from autotrack.pipeline import Pipeline
from autotrack.sessions import (
    Session,
    open_session,
    write_otb_tracks,
    write_tracks_csv,
    write_tum_poses,
)
from autotrack.sessions.exports import export_session_cvat, export_session_mot
from autotrack.sessions.snapshot import finished_copy

EXPORTS = ("tracks", "poses", "mot", "cvat", "mcap")
"""What `build` can make: the tracks zip, the TUM poses, the MOT Challenge tracks, the CVAT
for video 1.1 XML (drawn and corrected boxes as keyframes), the session file itself."""


def build(run: Pipeline, what: str) -> tuple[str, bytes]:
    """(file name, content) of a download of `run`'s recording: 'tracks', 'poses' or 'mcap'
    (a finished snapshot of the file being written). A run reopened only to look through (a
    live recording: no new file) exports the file it was reopened from."""
    path = run.session_path or (run.resumed_from if run.recording is None else None)
    if path is None:
        raise InputError("nothing recorded yet: draw a box and track first")
    with contextlib.suppress(OSError, AutoTrackError):  # a full disk: what the file holds
        run.flush()
    if what == "tracks":
        return f"{path.stem}_tracks.zip", tracks_zip(path)
    if what == "poses":
        return f"{path.stem}_poses.tum", poses_tum(path)
    if what == "mot":
        return f"{path.stem}_mot.txt", _written(path, "mot.txt", export_session_mot)
    if what == "cvat":
        size = run.frames.frame_size

        def cvat(session: Session, out: Path) -> object:
            return export_session_cvat(session, out, frame_size=size)

        return f"{path.stem}_cvat.xml", _written(path, "cvat.xml", cvat)
    if what == "mcap":
        return path.name, finished_copy(path)
    raise InputError(f"unknown export {what!r}; choose one of {EXPORTS}")


def tracks_zip(session_path: Path) -> bytes:
    """A zip of one OTB-style `<target>.txt` per target (1-based x, y) plus `tracks.csv`
    (0-based, with score and aberrance), read from the session file."""
    session = open_session(session_path)
    with tempfile.TemporaryDirectory(prefix="autotrack-export-", dir=_scratch()) as folder:
        folder_path = Path(folder)
        paths = write_otb_tracks(session, folder_path / "otb")
        csv_path = write_tracks_csv(session, folder_path / "tracks.csv")
        buffer = BytesIO()
        with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
            for path in paths:
                archive.write(path, arcname=path.name)
            archive.write(csv_path, arcname=csv_path.name)
    return buffer.getvalue()


def poses_tum(session_path: Path) -> bytes:
    """The session's valid camera poses in the TUM format (timestamp = frame index / fps)."""
    return _written(session_path, "poses.tum", write_tum_poses)


def _written(session_path: Path, name: str, write: Callable[[Session, Path], object]) -> bytes:
    """What one of the library's exporters writes for the session, as bytes."""
    session = open_session(session_path)
    with tempfile.TemporaryDirectory(prefix="autotrack-export-", dir=_scratch()) as folder:
        path = Path(folder) / name
        write(session, path)
        return path.read_bytes()


MEMORY_FOLDER = Path("/dev/shm")
"""A folder in memory (Linux): the exporters' scratch files, so a full disk blocks no download."""


def _scratch() -> Path | None:
    """Where an export's scratch files go: memory where the system offers it, else the
    temporary folder."""
    return MEMORY_FOLDER if os.access(MEMORY_FOLDER, os.W_OK | os.X_OK) else None
