"""The session metadata record: what a session file says about itself, written and read."""

from __future__ import annotations

import dataclasses
import json
import os
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


PATH_BYTES_SUFFIX = "_fs_hex"
"""A path that is not valid UTF-8 (a Latin-1 folder name, decoded by `os.fsdecode` with
surrogate escapes) is recorded as readable text (the odd bytes as `\\xe9`) under its key and,
exactly, as the hex of its bytes under `<key>_fs_hex`: MCAP strings are UTF-8."""


def path_entries(key: str, path: str | Path | None) -> dict[str, str]:
    """Metadata entries recording `path` (empty text for None), exactly also when it is not
    valid UTF-8 (`PATH_BYTES_SUFFIX`)."""
    if path is None:
        return {key: ""}
    text = str(path)
    shown = path_text(text)
    if shown == text:
        return {key: text}
    return {key: shown, key + PATH_BYTES_SUFFIX: os.fsencode(text).hex()}


def path_text(path: str | Path) -> str:
    """`path` as UTF-8 text: itself, or with the bytes that are not UTF-8 shown as `\\xe9`."""
    text = str(path)
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return os.fsencode(text).decode("utf-8", "backslashreplace")
    return text


def recorded_path(metadata: Mapping[str, Any], key: str) -> str:
    """The path recorded under `key` exactly as it was given (see `path_entries`)."""
    exact = metadata.get(key + PATH_BYTES_SUFFIX)
    if exact:
        try:
            return os.fsdecode(bytes.fromhex(str(exact)))
        except ValueError as error:
            raise SessionError(f"its {key}{PATH_BYTES_SUFFIX} is not hex") from error
    return str(metadata.get(key) or "")


def session_metadata(
    *,
    source: str,
    fps: float,
    fps_given: bool,
    tracker_params: TrackerParams | Mapping[str, Any],
    scene_path: str | Path | None,
    tracker: str | None = None,
    embed_frames: bool,
    record_maps: bool,
    flush_interval: float,
    resumed_from: str | Path | None,
    live_source: bool = False,
) -> dict[str, str]:
    """The session metadata record (every value a string, as MCAP metadata requires);
    `tracker` None: the preset `tracker_params` describe (none for a plain dict)."""
    params = params_dict(tracker_params)
    if tracker is None and isinstance(tracker_params, TrackerParams):
        tracker = tracker_params.name
    return {
        **path_entries("source", source),
        **path_entries("scene_path", scene_path),
        **path_entries("resumed_from", resumed_from),
        "format_version": str(FORMAT_VERSION),
        "package_version": autotrack.__version__,
        "mcap_version": getattr(mcap, "__version__", "unknown"),
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "fps": repr(fps),
        "fps_given": "true" if fps_given else "false",
        "tracker_params": json.dumps(params, sort_keys=True),
        "tracker": tracker or "",
        "embed_frames": "true" if embed_frames else "false",
        "record_maps": "true" if record_maps else "false",
        "live_source": "true" if live_source else "false",
        "map_encoding": "mono8, min-max per map: value = lo + q / 255 * (hi - lo), "
        "[lo, hi] in the target's signals message",
        "flush_interval_s": repr(flush_interval),
    }
