"""`autotrack session info|export FILE`: summarise a recorded session or export its tracks/poses."""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from autotrack.errors import SessionError
from autotrack.sessions import (
    Session,
    open_session,
    write_otb_tracks,
    write_tracks_csv,
    write_tum_poses,
)


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "session",
        help="inspect or export a recorded session (.mcap)",
        description="Inspect or export a session recorded by the app or `autotrack localize "
        "--session`. Files cut short by a crash are read up to the cut.",
    )
    actions = parser.add_subparsers(dest="session_command", required=True)

    info = actions.add_parser(
        "info", help="summary: frames, targets, poses, duration, whether it was cut short"
    )
    info.add_argument("file", type=Path, help="session file (.mcap)")
    info.add_argument("--json", action="store_true", help="print the summary as JSON")
    info.set_defaults(func=run_info)

    export = actions.add_parser(
        "export",
        help="write OTB-style tracks, a combined CSV and/or TUM poses",
        description="Export tracks as one OTB-style `<target>.txt` per target (x,y,w,h per frame, "
        "1-based x and y, NaN where absent), a combined CSV (frame, target, 0-based x,y,w,h, "
        "score, aberrant) and the valid camera poses as a TUM trajectory for evo "
        "(timestamp = frame index / fps).",
    )
    export.add_argument("file", type=Path, help="session file (.mcap)")
    export.add_argument("--tracks", type=Path, default=None, help="folder for <target>.txt files")
    export.add_argument("--poses", type=Path, default=None, help="TUM trajectory file to write")
    export.add_argument("--csv", type=Path, default=None, help="combined CSV file to write")
    export.add_argument("--mot", type=Path, default=None, help="MOT Challenge file to write")
    export.add_argument(
        "--cvat", type=Path, default=None, help="CVAT for video 1.1 XML file to write"
    )
    export.add_argument(
        "--cvat-all-keyframes",
        action="store_true",
        help="mark every box a keyframe (CVAT keeps only keyframes on import)",
    )
    export.add_argument(
        "--frame-size",
        type=str,
        default=None,
        metavar="WxH",
        help="frame size for --cvat when the session's source is not readable here",
    )
    export.add_argument(
        "--evo", action="store_true", help="print evo's APE command for --poses against --gt"
    )
    export.add_argument(
        "--gt",
        type=Path,
        default=None,
        help="ground-truth TUM for --evo (default: SOURCE/poses_gt.tum)",
    )
    export.add_argument(
        "--frames",
        type=Path,
        default=None,
        metavar="DIR",
        help="write the embedded frames to DIR as image files (their recorded bytes)",
    )
    export.add_argument("--force", action="store_true", help="replace existing output files")
    export.set_defaults(func=run_export)


def session_summary(session: Session) -> dict[str, Any]:
    """The figures `session info` prints, as plain JSON-able data."""
    targets = {}
    for target_id in session.exported_targets:  # as `export` writes them: deleted ones left out
        boxes = session.tracks[target_id]
        present = np.flatnonzero(np.isfinite(boxes).all(axis=1))
        targets[target_id] = {
            "frames": int(present.size),
            "first_frame": int(present[0]) if present.size else None,
            "last_frame": int(present[-1]) if present.size else None,
            "aberrant_frames": int(session.aberrant[target_id].sum()),
            "landmark_id": session.landmark_ids.get(target_id),
            "trusted": dict(Counter(str(v) for v in session.trusted.get(target_id, ()) if v)),
        }
    poses = session.poses
    return {
        "file": str(session.path),
        "format_version": session.format_version,
        "package_version": session.metadata.get("package_version"),
        "created_utc": session.metadata.get("created_utc"),
        "source": session.metadata.get("source"),  # as text (`path_text`)
        "tracker": session.tracker_name,
        "scene_path": session.metadata.get("scene_path") or None,
        "fps": session.fps,
        "frames": session.frame_count,
        "last_frame": _last_complete_frame(session),
        "partial_frame": session.partial_frame,
        "targets": targets,
        "deleted_targets": sorted(session.deleted_targets),
        "poses": {"frames": int(poses.frame_indices.size), "valid": int(poses.valid.sum())},
        "events": dict(Counter(event.kind for event in session.events)),
        "embedded_frames": session.image_count,
        "messages": session.message_count,
        "duration_s": session.duration_s,
        "wall_time_span_s": session.wall_time_span_s,
        "truncated": session.truncated,
        "being_recorded": session.being_recorded,
        "bytes_read": session.bytes_read,
        "file_size": session.file_size,
    }


def _last_complete_frame(session: Session) -> int | None:
    if not len(session.frame_indices):
        return None
    last = int(session.frame_indices[-1])
    return last - 1 if session.partial_frame == last else last


def _format_summary(summary: dict[str, Any]) -> str:
    lines = [
        f"session   {summary['file']}",
        f"format    version {summary['format_version']}, written by autotrack-studio "
        f"{summary['package_version']} on {summary['created_utc']}",
        f"source    {summary['source']}",
        f"tracker   {summary['tracker']}",
    ]
    if summary["scene_path"]:
        lines.append(f"scene     {summary['scene_path']}")
    last = summary["last_frame"]
    span = f"frames 0-{last}" if last is not None else "no frames"
    lines.append(f"frames    {summary['frames']} tracked ({span}) at {summary['fps']:g} fps")
    lines.append(
        f"duration  {summary['duration_s']:.2f} s of video, "
        f"{summary['wall_time_span_s']:.2f} s of recording"
    )
    deleted = summary["deleted_targets"]
    gone = f" ({len(deleted)} deleted: {', '.join(deleted)})" if deleted else ""
    lines.append(f"targets   {len(summary['targets'])}{gone}")
    for target_id, target in summary["targets"].items():
        extent = (
            f"frames {target['first_frame']}-{target['last_frame']}"
            if target["frames"]
            else "no boxes"
        )
        landmark = f", landmark {target['landmark_id']}" if target["landmark_id"] else ""
        trusted = ", ".join(f"{name} {count}" for name, count in target["trusted"].items())
        lines.append(
            f"  {target_id}: {target['frames']} boxes ({extent}), "
            f"{target['aberrant_frames']} aberrant{landmark}"
            + (f"; trusted {trusted}" if trusted else "")
        )
    poses = summary["poses"]
    lines.append(f"poses     {poses['valid']} valid of {poses['frames']}")
    events = ", ".join(f"{count} {kind}" for kind, count in summary["events"].items())
    lines.append(f"events    {events or 'none'}")
    if summary["embedded_frames"]:
        lines.append(f"images    {summary['embedded_frames']} embedded frames")
    if summary["being_recorded"]:
        lines.append(
            f"complete  not yet: being recorded; read {summary['messages']} messages from the "
            f"first {summary['bytes_read']} of {summary['file_size']} bytes so far"
        )
    elif summary["truncated"]:
        lines.append(
            f"complete  NO: cut short (crash or interrupted copy); read {summary['messages']} "
            f"messages from the first {summary['bytes_read']} of {summary['file_size']} bytes"
        )
        if summary["partial_frame"] is not None:
            lines.append(
                f"          frame {summary['partial_frame']} was only partly written before the "
                "cut: not counted"
            )
    else:
        lines.append(f"complete  yes ({summary['messages']} messages)")
    return "\n".join(lines)


def run_info(args: argparse.Namespace) -> int:
    summary = session_summary(open_session(args.file))
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(_format_summary(summary))
    return 0


def run_export(args: argparse.Namespace) -> int:
    outputs = ("tracks", "poses", "csv", "mot", "cvat", "frames")
    if not any(getattr(args, name) for name in outputs):
        raise SessionError(
            "nothing to export: give --tracks DIR, --poses FILE, --csv FILE, --mot FILE, "
            "--cvat FILE and/or --frames DIR"
        )
    if args.evo and args.poses is None:
        raise SessionError("--evo prints the command for the exported poses: give --poses FILE")
    session = open_session(args.file)
    if args.cvat is not None:  # before writing anything: the frame size CVAT needs
        from autotrack.sessions.exports import session_frame_size

        args.frame_size = _frame_size(args.frame_size) or session_frame_size(session)
        if args.frame_size is None:
            raise SessionError(
                f"the session's source {session.metadata.get('source')} cannot be read here "
                "to get the frame size CVAT needs: give --frame-size WIDTHxHEIGHT"
            )
    if args.frames is not None and not session.image_count:
        raise SessionError(f"{args.file} embeds no frames (it was recorded with --no-frames)")
    if session.being_recorded:
        print(f"note: {args.file} is still being recorded; exporting what was recorded so far")
    elif session.truncated:
        print(f"note: {args.file} was cut short; exporting what was recorded before the cut")
    if args.tracks is not None:
        paths = write_otb_tracks(session, args.tracks, overwrite=args.force)
        print(f"wrote {len(paths)} track file(s) to {args.tracks}")
    if args.csv is not None:
        write_tracks_csv(session, args.csv, overwrite=args.force)
        print(f"wrote {args.csv}")
    if args.poses is not None:
        count = write_tum_poses(session, args.poses, overwrite=args.force)
        print(f"wrote {count} valid pose(s) to {args.poses}")
    _export_interchange(session, args)
    if args.frames is not None:
        from autotrack.sessions.frames import write_frames

        count = write_frames(session, args.frames, force=args.force)
        print(f"wrote {count} frame(s) to {args.frames}")
    return 0


def _frame_size(text: str | None) -> tuple[int, int] | None:
    """'1280x720' -> (1280, 720); SessionError for anything else."""
    if text is None:
        return None
    width, _, height = text.lower().partition("x")
    if not (width.isdigit() and height.isdigit() and int(width) > 0 and int(height) > 0):
        raise SessionError(
            f"--frame-size must be WIDTHxHEIGHT in pixels (e.g. 1280x720), got {text!r}"
        )
    return (int(width), int(height))


def _export_interchange(session: Session, args: argparse.Namespace) -> None:
    """--mot, --cvat and --evo (autotrack.sessions.exports)."""
    from autotrack.sessions.exports import (
        evo_ape_command,
        export_session_cvat,
        export_session_mot,
    )

    if args.mot is not None:
        ids = export_session_mot(session, args.mot, overwrite=args.force)
        mapping = ", ".join(f"{target}={number}" for target, number in ids.items())
        print(f"wrote {args.mot} (MOT ids: {mapping})")
    if args.cvat is not None:
        export_session_cvat(
            session,
            args.cvat,
            overwrite=args.force,
            all_keyframes=args.cvat_all_keyframes,
            frame_size=args.frame_size,
        )
        print(f"wrote {args.cvat} (CVAT for video 1.1)")
    if args.evo:
        print(evo_ape_command(session, args.poses, args.gt))
