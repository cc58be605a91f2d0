"""The session metadata record: what a session file says about itself, written and read."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import mcap

import autotrack
from autotrack.errors import SessionError
from autotrack.params import TrackerParams
from autotrack.sessions.encoding import FORMAT_VERSION, jsonable


def params_dict(tracker_params: TrackerParams | Mapping[str, Any]) -> dict[str, Any]:
    """Tracker parameters as plain JSON data."""
    if isinstance(tracker_params, TrackerParams):
        return jsonable(dataclasses.asdict(tracker_params))
    if isinstance(tracker_params, Mapping):
        return jsonable(dict(tracker_params))
    raise SessionError(
        f"tracker_params must be TrackerParams or a dict, got {type(tracker_params).__name__}"
    )


def session_metadata(
    *,
    source: str,
    fps: float,
    fps_given: bool,
    params: dict[str, Any],
    scene_path: str | Path | None,
    embed_frames: bool,
    record_maps: bool,
    flush_interval: float,
    resumed_from: str | Path | None,
) -> dict[str, str]:
    """The session metadata record (every value a string, as MCAP metadata requires)."""
    return {
        "format_version": str(FORMAT_VERSION),
        "package_version": autotrack.__version__,
        "mcap_version": getattr(mcap, "__version__", "unknown"),
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "source": str(source),
        "fps": repr(fps),
        "fps_given": "true" if fps_given else "false",
        "tracker_params": json.dumps(params, sort_keys=True),
        "scene_path": str(scene_path) if scene_path is not None else "",
        "embed_frames": "true" if embed_frames else "false",
        "record_maps": "true" if record_maps else "false",
        "map_encoding": "mono8, min-max per map: value = lo + q / 255 * (hi - lo), "
        "[lo, hi] in the target's signals message",
        "flush_interval_s": repr(flush_interval),
        "resumed_from": str(resumed_from) if resumed_from is not None else "",
    }
