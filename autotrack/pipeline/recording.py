"""Where a pipeline records its session, and opening that recorder."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from autotrack.errors import InputError
from autotrack.io.frames import FrameSource
from autotrack.params import TrackerParams
from autotrack.sessions import SessionRecorder


@dataclass(frozen=True)
class Recording:
    """Where the pipeline records its session; the file is created at the first edit."""

    source: str
    """What the session names as its source (the sequence path)."""
    directory: Path | None = None
    """A NEW file `<directory>/<UTC time>_<name>.mcap` (SessionRecorder.create)."""
    path: Path | None = None
    """Or exactly this new file (never overwritten)."""
    name: str | None = None
    """Name part of the file in `directory` (default: the frames' name)."""
    scene_path: Path | None = None
    """The scene file, recorded in the metadata and attached."""
    record_maps: bool = True
    """Record each target's response and local-variation maps and spatial weights (mono8)."""
    embed_frames: bool = True
    """Embed every tracked frame on the camera topic, so the recording replays as the annotated
    video (a JPEG or PNG file's bytes as they are, other frames encoded once as JPEG); about as
    large as the frames' files. False: boxes, signals, maps and poses only."""


def open_recorder(
    recording: Recording,
    params: TrackerParams,
    tracker: str,
    fps: float | None,
    resumed_from: Path | None,
    frames: FrameSource,
) -> SessionRecorder:
    """A new SessionRecorder for `recording` (the file is created here); `tracker` names the
    tracker `params` are for (`Pipeline.tracker_name`)."""
    options = {
        "source": recording.source,
        "tracker_params": params,
        "tracker": tracker,
        "scene_path": recording.scene_path,
        "fps": fps,
        "resumed_from": resumed_from,
        "record_maps": recording.record_maps,
        "embed_frames": recording.embed_frames,
        "live_source": frames.live,
    }
    if recording.path is not None:
        return SessionRecorder(recording.path, **options)
    if recording.directory is None:
        raise InputError("a recording needs a directory or a path")
    return SessionRecorder.create(
        recording.directory, name=recording.name or frames.name, **options
    )
