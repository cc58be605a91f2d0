"""Identifiers that enter from files and users (landmark ids): checked where they enter.

An id ends up in file names, CSV cells, MCAP topics and the app's tables, so a newline or
another control character in one could inject a row or break a file long after it was typed;
it is refused at once, before any file is created.
"""

from __future__ import annotations

MAX_ID_LENGTH = 128
"""Longest identifier accepted (characters)."""


def identifier_problem(value: object) -> str | None:
    """Why `value` cannot be an identifier (None: it can): not a string, blank, too long, or
    holding a control or other non-printable character."""
    if not isinstance(value, str):
        return f"must be a string, got {type(value).__name__}"
    if not value.strip():
        return "must not be empty"
    if len(value) > MAX_ID_LENGTH:
        return f"is longer than {MAX_ID_LENGTH} characters"
    if not value.isprintable():
        return "holds a control character (newline, tab, NUL, ...)"
    return None


def checked_identifier(value: object, what: str, error: type[Exception]) -> str:
    """`value` as an identifier, or `error` naming `what` and the problem."""
    problem = identifier_problem(value)
    if problem is not None:
        raise error(f"{what} {value!r} {problem}")
    assert isinstance(value, str)
    return value
