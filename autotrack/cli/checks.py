"""Checks every command makes before any work starts: output paths, numeric options, boxes.

A run that tracks every frame and then cannot write its result loses it all, so an output path
that cannot be written (a folder, a read-only place, a missing parent that cannot be made) or
that would overwrite a file without `--force` ends the command at once, in one line.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from autotrack.errors import BoxError, InputError
from autotrack.hybrid.factory import SIAMESE_TRACKERS, TRACKERS, make_tracker, tracker_params
from autotrack.params import TrackerParams
from autotrack.tracker.inputs import validate_box

if TYPE_CHECKING:
    from autotrack.pipeline import Recording


def _nearest_existing(path: Path) -> Path:
    """`path` or its closest ancestor that exists."""
    current = path.absolute()
    while not current.exists() and current != current.parent:
        current = current.parent
    return current


def add_session_arguments(parser: argparse.ArgumentParser) -> None:
    """--session FILE (the run recorded to MCAP, its frames embedded) and --no-frames."""
    parser.add_argument(
        "--session",
        type=Path,
        default=None,
        metavar="FILE",
        help="record the run to this new MCAP session file (never overwritten; see "
        "`autotrack session`), the tracked frames embedded",
    )
    parser.add_argument(
        "--no-frames",
        action="store_true",
        help="with --session: do not embed the tracked frames (a much smaller file that "
        "replays without its footage)",
    )


def session_recording(args: argparse.Namespace, scene_path: Path | None = None) -> Recording | None:
    """The recording `--session` asks for (None without it): the tracked frames embedded unless
    `--no-frames`."""
    if args.session is None:
        return None
    from autotrack.pipeline import Recording

    return Recording(
        source=str(args.sequence),
        path=args.session,
        scene_path=scene_path,
        embed_frames=not args.no_frames,
    )


def add_tracker_argument(parser: argparse.ArgumentParser) -> None:
    """--preset NAME: an AutoTrack preset, `nanotrack` or `hybrid` (`autotrack.hybrid.factory`)."""
    parser.add_argument(
        "--preset",
        default="autotrack",
        choices=TRACKERS,
        help="the tracker: an AutoTrack preset, nanotrack (NanoTrack V2) or hybrid "
        "(autotrack+ and NanoTrack fused); default autotrack",
    )


def chosen_tracker(
    args: argparse.Namespace, colour_table: Path | None = None
) -> tuple[str, TrackerParams]:
    """--preset's tracker name and the parameters it runs with; NanoTrack's model files are
    loaded once here, so a broken install ends the command before any work, in one line."""
    params = tracker_params(args.preset, colour_table)
    if args.preset in SIAMESE_TRACKERS:
        make_tracker(args.preset, params)
    return args.preset, params


def check_session_file(path: Path | None) -> None:
    """--session names a file that does not exist yet (session files are never replaced) and
    can be created."""
    if path is not None and (path.exists() or path.is_symlink()):
        raise InputError(f"--session {path} exists; session files are never replaced")
    check_output_file(path, "--session", force=False)


def check_output_file(path: Path | None, option: str, *, force: bool) -> None:
    """`path` can be written as a file: not a folder, not an existing file unless `force`,
    and its folder exists or can be made, writable."""
    if path is None:
        return
    if path.is_dir():
        raise InputError(f"{option} {path} is a folder; give a file name")
    if path.exists() or path.is_symlink():
        if not force:
            raise InputError(f"{option} {path} exists; pass --force to replace it")
        if not os.access(path, os.W_OK):
            raise InputError(f"{option} {path} cannot be written (permission denied)")
    check_output_folder(path.parent, option)


def check_output_folder(folder: Path, option: str) -> None:
    """`folder` exists as a writable folder, or can be made inside one."""
    existing = _nearest_existing(folder)
    if not existing.is_dir():
        raise InputError(f"{option}: {existing} is not a folder, so {folder} cannot be made")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"{option}: cannot write into {existing} (permission denied)")


def finite(value: float | None, option: str, *, low: float = -math.inf, high: float = math.inf):
    """`value` unless it is NaN, infinite or outside (low, high]; None passes."""
    if value is None:
        return None
    if not math.isfinite(value) or not low < value <= high:
        bounds = f" in ({low:g}, {high:g}]" if math.isfinite(high) else f" above {low:g}"
        raise InputError(f"{option} must be a finite number{bounds}, got {value!r}")
    return value


def parse_box(text: str) -> tuple[float, float, float, float]:
    """'x,y,w,h' -> four floats, with a message naming what is wrong."""
    fields = [field.strip() for field in text.replace(" ", ",").split(",") if field.strip()]
    if len(fields) != 4:
        raise BoxError(f"--init must be four numbers x,y,w,h; got {text!r}")
    try:
        x, y, w, h = (float(field) for field in fields)
    except ValueError as error:
        raise BoxError(f"--init must be four numbers x,y,w,h; got {text!r}") from error
    return (x, y, w, h)


def init_box(text: str, frame_size_wh: tuple[int, int]) -> np.ndarray:
    """The 0-based box of `--init TEXT` (1-based x,y,w,h), checked against the frame size with
    messages that quote what the user typed."""
    box = np.array(parse_box(text)) - np.array([1.0, 1.0, 0.0, 0.0])
    validate_box(box, frame_size_wh, name=f"--init {text} (1-based x,y,w,h)")
    return box
