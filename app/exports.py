"""Files offered for download, built from a session recording by the library's exporters."""

from __future__ import annotations

import tempfile
import zipfile
from io import BytesIO
from pathlib import Path

from autotrack.sessions import open_session, write_otb_tracks, write_tracks_csv, write_tum_poses


def tracks_zip(session_path: Path) -> bytes:
    """A zip of one OTB-style `<target>.txt` per target (1-based x, y) plus `tracks.csv`
    (0-based, with score and aberrance), read from the session file."""
    session = open_session(session_path)
    with tempfile.TemporaryDirectory(prefix="autotrack-export-") as folder:
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
    session = open_session(session_path)
    with tempfile.TemporaryDirectory(prefix="autotrack-export-") as folder:
        path = Path(folder) / "poses.tum"
        write_tum_poses(session, path)
        return path.read_bytes()
