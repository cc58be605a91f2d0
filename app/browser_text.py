"""Text made safe for the browser: names that are not UTF-8, and markdown that is not ours.

Two ways text from outside (file names on the server, what a user typed, a scene file's
landmark names) breaks a page:

- a file name whose bytes are not UTF-8 (a Latin-1 folder in a shared data folder) reaches
  Python as surrogate escapes, which viser's message encoder refuses: the tab's websocket
  closes. `readable` writes those bytes as backslash escapes (`caf\\xe9`); the server keeps the
  real path, and app/paths.py's `resolve_user_path` takes the escaped spelling back;
- the status line is markdown, which viser renders with raw HTML allowed: a typed
  `<img src=...>` would be fetched, a `<style>` applied. `markdown_literal` makes any text
  show as the characters it is.
"""

from __future__ import annotations

import html
import re

_MARKDOWN_PUNCTUATION = re.compile(r"([\\`*\[\]!|~])")
"""Characters by which markdown makes links, images, code, emphasis or tables (escaped with a
backslash; `<`, `>` and `&` become entities, so no HTML and no autolink gets through)."""


def readable(text: str) -> str:
    """`text` with the bytes of a non-UTF-8 file name as backslash escapes (`\\xe9`), so any
    UTF-8 encoder takes it; valid text is unchanged."""
    try:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:  # a surrogate no file name decodes to
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


def markdown_literal(text: str) -> str:
    """`text` as markdown that shows exactly these characters: HTML written as entities,
    markdown punctuation escaped, line breaks kept (as markdown's hard breaks)."""
    escaped = _MARKDOWN_PUNCTUATION.sub(r"\\\1", html.escape(readable(text), quote=False))
    return "  \n".join(escaped.splitlines()) if "\n" in escaped else escaped
