"""Whose sessions and uploads a tab sees: one space per browser, unless the server shares.

A browser is known by the random `autotrack_browser_PORT` cookie the page's answer sets
(`app/access.py`; `HttpOnly`, `SameSite=Strict`). Its recordings go to
`SESSIONS/browser-<tag>/` and its uploads to `SESSIONS/uploads/browser-<tag>/`, where `<tag>`
is a hash of the cookie (the cookie itself is never written to disk). A tab lists the session
files directly in `SESSIONS/` (put there by the operator, e.g. CLI recordings: everyone's)
and those of its own browser, and may open only its own uploads. A connection without the
cookie gets a space of its own that no other tab shares. With `--share-sessions` every tab
lists every browser's sessions and may open every upload.
"""

from __future__ import annotations

import contextlib
import hashlib
import secrets
from dataclasses import dataclass
from pathlib import Path

SPACE_PREFIX = "browser-"
"""Name prefix of a browser's folders under the sessions and uploads folders."""


def browser_tag(browser_id: str | None) -> str:
    """The folder tag of a browser (a hash of its cookie); a fresh one when unknown."""
    if browser_id is None:
        return secrets.token_hex(8)
    return hashlib.sha256(browser_id.encode("utf-8")).hexdigest()[:16]


@dataclass(frozen=True)
class BrowserSpace:
    """Where one browser's recordings and uploads go, and what its tabs may list and open."""

    sessions_root: Path
    """The server's sessions folder."""
    upload_root: Path
    """The server's uploads folder."""
    tag: str | None
    """This browser's folder tag (None: no browser, the folders themselves, as the library
    API without a server uses them; everything is listed)."""
    shared: bool = False
    """The server was started with --share-sessions: every browser's files are listed."""

    @property
    def sessions_dir(self) -> Path:
        """Where this browser's recordings are written."""
        if self.tag is None:
            return self.sessions_root
        return self.sessions_root / f"{SPACE_PREFIX}{self.tag}"

    @property
    def upload_dir(self) -> Path:
        """Where this browser's uploads are stored."""
        if self.tag is None:
            return self.upload_root
        return self.upload_root / f"{SPACE_PREFIX}{self.tag}"

    @property
    def sees_everything(self) -> bool:
        """Every browser's sessions and uploads are listed to this one."""
        return self.shared or self.tag is None

    def hides(self, path: Path) -> bool:
        """`path` lies in another browser's folder (of sessions or uploads), which this one
        may not open even when an allowed root holds it."""
        if self.sees_everything:
            return False
        resolved = path.resolve()
        for root, own in (
            (self.sessions_root, self.sessions_dir),
            (self.upload_root, self.upload_dir),
        ):
            root = root.resolve()
            if resolved.is_relative_to(root) and resolved != root:
                first = resolved.relative_to(root).parts[0]
                if first.startswith(SPACE_PREFIX) and first != own.name:
                    return True
        return False

    def upload_roots(self) -> tuple[Path, ...]:
        """The upload folders this browser's tabs may open things from (made if missing)."""
        folder = self.upload_root if self.sees_everything else self.upload_dir
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except FileExistsError:
            if folder.exists():
                raise  # a file in its place
            # A closing tab of this browser removed the empty folder (`release`) between
            # mkdir finding it and checking it is a folder: made again.
            folder.mkdir(parents=True, exist_ok=True)
        return (folder,)

    def session_files(self) -> list[Path]:
        """The session files this browser may list and reopen, newest first."""
        folders = [self.sessions_root]
        if self.sees_everything:
            folders += sorted(self.sessions_root.glob(f"{SPACE_PREFIX}*"))
        else:
            folders.append(self.sessions_dir)
        files = [path for folder in folders for path in folder.glob("*.mcap") if path.is_file()]
        return sorted(files, key=lambda path: path.stat().st_mtime, reverse=True)

    def release(self) -> None:
        """Remove this browser's folders if nothing was written to them (a tab that never
        uploaded or recorded leaves no empty folder behind)."""
        if self.tag is None:
            return
        for folder in (self.upload_dir, self.sessions_dir):
            with contextlib.suppress(OSError):
                folder.rmdir()
