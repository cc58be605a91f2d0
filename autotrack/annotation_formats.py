"""Tracks in the formats annotation and evaluation tools read: MOT Challenge text and CVAT for
video 1.1 XML, written and read back.

Both take tracks as target id -> (N, 4) array of 0-based x, y, w, h boxes, row i = frame i, NaN
rows where the target has no box (what `autotrack.sessions.Session.tracks` holds).

**MOT Challenge** (the tracker-output layout of the MOT benchmarks and py-motmetrics): one line
per frame and target, ``frame,id,bb_left,bb_top,bb_width,bb_height,conf,-1,-1,-1``; frames
count from 1 and the box corner is 1-based, as in the benchmarks' own files (and our OTB-style
box files); ids are integers from 1 in target order.

**CVAT for video 1.1** (CVAT's "CVAT for video 1.1" import/export format, see its XML format
documentation): ``<annotations><version>1.1</version><meta><task>...</task></meta>`` then one
``<track id label source>`` per target holding ``<box frame keyframe outside occluded xtl ytl
xbr ybr z_order>`` elements, in 0-based continuous pixel coordinates (xbr = x + w). A track
starts with a keyframe, and where the target disappears (a NaN row, or the end of the video
before the last frame) a box with ``outside="1"`` closes the visible stretch, as CVAT writes
it. Frames the user drew or corrected are keyframes; CVAT keeps only keyframes when it imports
a track and interpolates linearly between them, so `all_keyframes=True` marks every tracked box
a keyframe to keep the tracker's boxes as they are.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from autotrack.errors import InputError, SessionError

if TYPE_CHECKING:
    from autotrack.sessions import Session

CVAT_VERSION = "1.1"
"""The CVAT XML format version written."""

CVAT_SOURCE = "auto"
"""The `source` of every written track (CVAT's value for automatically produced tracks)."""


def _visible(boxes: np.ndarray) -> np.ndarray:
    return np.isfinite(boxes).all(axis=1) & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)


def _as_boxes(target_id: str, boxes: np.ndarray) -> np.ndarray:
    array = np.asarray(boxes, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 4:
        raise InputError(f"track {target_id}: boxes must be N x 4, got shape {array.shape}")
    return array


# --- MOT Challenge ---------------------------------------------------------------------------


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
        boxes = _as_boxes(target_id, tracks[target_id])
        target_scores = None if scores is None else scores.get(target_id)
        for frame_index in np.flatnonzero(_visible(boxes)):
            x, y, w, h = boxes[frame_index]
            conf = 1.0
            if target_scores is not None and np.isfinite(target_scores[frame_index]):
                conf = float(target_scores[frame_index])
            text = f"{frame_index + 1},{number},{x + 1:.2f},{y + 1:.2f},{w:.2f},{h:.2f},{conf:.4f}"
            rows.append((int(frame_index), number, text + ",-1,-1,-1"))
    rows.sort()
    Path(path).write_text("".join(f"{text}\n" for _, _, text in rows), encoding="utf-8")
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


# --- CVAT for video 1.1 ------------------------------------------------------------------------


def _sub(parent: ElementTree.Element, tag: str, text: str | None = None) -> ElementTree.Element:
    element = ElementTree.SubElement(parent, tag)
    if text is not None:
        element.text = text
    return element


def _box_element(
    track: ElementTree.Element, frame: int, box: np.ndarray, *, keyframe: bool, outside: bool
) -> None:
    x, y, w, h = (float(v) for v in box)
    ElementTree.SubElement(
        track,
        "box",
        {
            "frame": str(frame),
            "keyframe": str(int(keyframe)),
            "outside": str(int(outside)),
            "occluded": "0",
            "xtl": f"{x:.2f}",
            "ytl": f"{y:.2f}",
            "xbr": f"{x + w:.2f}",
            "ybr": f"{y + h:.2f}",
            "z_order": "0",
        },
    )


def write_cvat_video(
    path: str | Path,
    tracks: Mapping[str, np.ndarray],
    *,
    keyframes: Mapping[str, Collection[int]] | None = None,
    all_keyframes: bool = False,
    frame_size: tuple[int, int] | None = None,
    task_name: str = "autotrack",
    label: str | None = None,
) -> Path:
    """Write the tracks as a CVAT for video 1.1 XML file, one `<track>` per target.

    `keyframes`: target id -> frames the user drew or corrected (keyframe="1"; the first box of
    each visible stretch is always one). `all_keyframes`: every box is a keyframe. `frame_size`
    (width, height) fills `<original_size>` (CVAT's readers expect it for video tasks). `label`: one label for every track; by default
    each track's label is its target id (CVAT needs the labels to exist in the task).
    """
    frame_count = max((len(boxes) for boxes in tracks.values()), default=0)
    root = ElementTree.Element("annotations")
    _sub(root, "version", CVAT_VERSION)
    task = _sub(_sub(root, "meta"), "task")
    now = datetime.now(UTC).isoformat(sep=" ", timespec="seconds")
    for tag, text in (
        ("id", "0"),
        ("name", task_name),
        ("size", str(frame_count)),
        ("mode", "interpolation"),
        ("overlap", "0"),
        ("bugtracker", ""),
        ("flipped", "False"),
        ("created", now),
        ("updated", now),
        ("start_frame", "0"),
        ("stop_frame", str(max(frame_count - 1, 0))),
        ("frame_filter", ""),
    ):
        _sub(task, tag, text)
    labels = _sub(task, "labels")
    for name in dict.fromkeys([label] if label is not None else list(tracks)):
        entry = _sub(labels, "label")
        _sub(entry, "name", name)
        _sub(entry, "type", "rectangle")
        _sub(entry, "attributes")
    if frame_size is not None:
        size = _sub(task, "original_size")
        _sub(size, "width", str(int(frame_size[0])))
        _sub(size, "height", str(int(frame_size[1])))
    _sub(root.find("meta"), "dumped", now)

    for track_number, (target_id, raw_boxes) in enumerate(tracks.items()):
        boxes = _as_boxes(target_id, raw_boxes)
        marked = set(keyframes.get(target_id, ())) if keyframes else set()
        track = ElementTree.SubElement(
            root,
            "track",
            {"id": str(track_number), "label": label or target_id, "source": CVAT_SOURCE},
        )
        visible = _visible(boxes)
        for frame in range(len(boxes)):
            if visible[frame]:
                starts = frame == 0 or not visible[frame - 1]
                keyframe = all_keyframes or starts or frame in marked
                _box_element(track, frame, boxes[frame], keyframe=keyframe, outside=False)
            elif frame > 0 and visible[frame - 1]:
                _box_element(track, frame, boxes[frame - 1], keyframe=True, outside=True)
    ElementTree.indent(root)
    path = Path(path)
    ElementTree.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path


@dataclass(frozen=True)
class CvatTrack:
    """One `<track>` of a CVAT for video file, read back."""

    track_id: int
    label: str
    boxes: np.ndarray
    """(N, 4) 0-based x, y, w, h per frame; NaN outside the track and where outside="1"."""
    keyframes: frozenset[int] = field(default_factory=frozenset)
    """Frames of the visible boxes marked keyframe="1"."""
    outside: frozenset[int] = field(default_factory=frozenset)
    """Frames of the outside="1" boxes (where the target left the view)."""


def read_cvat_video(path: str | Path) -> tuple[dict[str, str], list[CvatTrack]]:
    """Read a CVAT for video 1.1 XML file: the task meta (tag -> text) and its box tracks, as
    CVAT exports them (every frame of a track written); InputError for other files."""
    path = Path(path)
    try:
        root = ElementTree.parse(path).getroot()
    except (OSError, ElementTree.ParseError) as error:
        raise InputError(f"cannot read CVAT XML {path}: {error}") from error
    version = root.findtext("version")
    if root.tag != "annotations" or version != CVAT_VERSION:
        raise InputError(f"{path} is not CVAT for video {CVAT_VERSION} XML (version {version})")
    task = root.find("meta/task")
    meta = {child.tag: (child.text or "") for child in task} if task is not None else {}
    try:
        size = int(meta.get("size", "0"))
    except ValueError:
        raise InputError(f"{path}: <size> is not a frame count") from None
    tracks = []
    try:
        for element in root.findall("track"):
            tracks.append(_read_track(element, size))
    except (TypeError, ValueError, IndexError) as error:
        raise InputError(f"{path}: malformed <track> or <box> ({error})") from None
    return meta, tracks


def _read_track(element: ElementTree.Element, size: int) -> CvatTrack:
    boxes = np.full((size, 4), np.nan)
    keyframes, outside = set(), set()
    for box in element.findall("box"):
        frame = int(box.get("frame"))
        if not 0 <= frame < size:
            raise ValueError(f"frame {frame} outside the task's {size} frames")
        xtl, ytl, xbr, ybr = (float(box.get(key)) for key in ("xtl", "ytl", "xbr", "ybr"))
        if box.get("outside") == "1":
            outside.add(frame)
            continue
        boxes[frame] = (xtl, ytl, xbr - xtl, ybr - ytl)
        if box.get("keyframe") == "1":
            keyframes.add(frame)
    return CvatTrack(
        int(element.get("id")),
        element.get("label", ""),
        boxes,
        frozenset(keyframes),
        frozenset(outside),
    )


# --- from a recorded session -------------------------------------------------------------------

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
    from autotrack.frames import open_frames

    source = session.metadata.get("source")
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
    """The session's tracks (deleted targets left out) as a MOT Challenge file; returns target
    id -> MOT id."""
    path = Path(path)
    _refuse_existing(path, overwrite)
    targets = session.exported_targets
    try:
        return write_mot(
            path, {t: session.tracks[t] for t in targets}, {t: session.scores[t] for t in targets}
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
    """The session's tracks as CVAT for video 1.1 XML, the user's drawn and corrected frames as
    keyframes (every box with `all_keyframes`).

    `frame_size` (width, height) defaults to the size of the session's source frames; CVAT's
    readers need it (<original_size>), so SessionError when neither is available.
    """
    path = Path(path)
    _refuse_existing(path, overwrite)
    frame_size = frame_size or session_frame_size(session)
    source = str(session.metadata.get("source") or session.path.stem)
    if frame_size is None:
        raise SessionError(
            f"the session's source {source} cannot be read here to get the frame size CVAT "
            "needs: give --frame-size WIDTHxHEIGHT"
        )
    try:
        return write_cvat_video(
            path,
            {t: session.tracks[t] for t in session.exported_targets},
            keyframes=session_keyframes(session),
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
    import shlex

    if ground_truth is None:
        source = session.metadata.get("source")
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
