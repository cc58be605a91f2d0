"""CVAT for video 1.1 XML (CVAT's "CVAT for video 1.1" import/export format, see its XML format
documentation), written and read back.

``<annotations><version>1.1</version><meta><task>...</task></meta>`` then one ``<track id label
source>`` per target holding ``<box frame keyframe outside occluded xtl ytl xbr ybr z_order>``
elements, in 0-based continuous pixel coordinates (xbr = x + w). A track starts with a keyframe,
and where the target disappears (a NaN row, or the end of the video before the last frame) a box
with ``outside="1"`` closes the visible stretch, as CVAT writes it. Frames the user drew or
corrected are keyframes; CVAT keeps only keyframes when it imports a track and interpolates
linearly between them, so `all_keyframes=True` marks every tracked box a keyframe to keep the
tracker's boxes as they are. Tracks are as in `autotrack.io.mot`: target id -> (N, 4) 0-based
x, y, w, h, NaN rows where the target has no box.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from autotrack.errors import InputError
from autotrack.io.atomic import write_bytes
from autotrack.io.mot import track_boxes, visible_rows

CVAT_VERSION = "1.1"
"""The CVAT XML format version written."""

CVAT_SOURCE = "auto"
"""The `source` of every written track (CVAT's value for automatically produced tracks)."""


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
        boxes = track_boxes(target_id, raw_boxes)
        marked = set(keyframes.get(target_id, ())) if keyframes else set()
        track = ElementTree.SubElement(
            root,
            "track",
            {"id": str(track_number), "label": label or target_id, "source": CVAT_SOURCE},
        )
        visible = visible_rows(boxes)
        for frame in range(len(boxes)):
            if visible[frame]:
                starts = frame == 0 or not visible[frame - 1]
                keyframe = all_keyframes or starts or frame in marked
                _box_element(track, frame, boxes[frame], keyframe=keyframe, outside=False)
            elif frame > 0 and visible[frame - 1]:
                _box_element(track, frame, boxes[frame - 1], keyframe=True, outside=True)
    ElementTree.indent(root)
    path = Path(path)
    write_bytes(path, ElementTree.tostring(root, encoding="utf-8", xml_declaration=True))
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
