"""What a recorder accepts as names: target ids, event kinds, landmark ids, file names.

Target ids appear in topic and file names, so they keep to a small alphabet; landmark ids come
from scene files and boxes.json and only must not hold control characters (`autotrack.io.ids`).
"""

from __future__ import annotations

import re

from autotrack.errors import SessionError
from autotrack.io.ids import checked_identifier

_TARGET_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
_EVENT_KIND = re.compile(r"^[a-z][a-z0-9_]{0,63}$")


def check_target_id(target_id: str) -> str:
    """`target_id` as a string, or SessionError when it cannot name topics and files."""
    target_id = str(target_id)
    if not _TARGET_ID.match(target_id):
        raise SessionError(
            f"target id {target_id!r} cannot be recorded: use 1-64 letters, digits, '_', '-' "
            "or '.', starting with a letter or digit"
        )
    return target_id


def check_landmark_id(landmark_id: str | None) -> None:
    """SessionError when a landmark id holds a control character (None passes)."""
    if landmark_id is not None:
        checked_identifier(landmark_id, "landmark id", SessionError)


def check_event_kind(kind: str) -> str:
    """`kind` when it is lower_snake_case, else SessionError."""
    if not _EVENT_KIND.match(str(kind)):
        raise SessionError(f"event kind {kind!r} must be lower_snake_case, e.g. 'box_drawn'")
    return str(kind)


def safe_file_name(name: str) -> str:
    """`name` reduced to letters, digits, '_', '.' and '-' (at most 80), for a session file."""
    cleaned = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._-")
    return cleaned[:80] or "session"
