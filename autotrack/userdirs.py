"""The per-user folders of the tool: one cache root, one data folder (XDG base directories).

- cache (`cache_root`): everything the tool keeps to go faster and can rebuild (compiled
  kernels, FFT plans, tables): `$AUTOTRACK_CACHE_DIR`, else `$XDG_CACHE_HOME/autotrack`, else
  `~/.cache/autotrack`; a temporary folder when none of them is writable.
- data (`data_root`): what the user made and would miss (the app's session recordings and
  uploads): `$XDG_DATA_HOME/autotrack`, else `~/.local/share/autotrack`.

Nothing is written to the current folder unless a command is told to. Standard library only:
this module runs before numba is imported.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

TOOL_FOLDER = "autotrack"
"""Name of the tool's folder inside the user's cache and data folders."""
CACHE_ENV = "AUTOTRACK_CACHE_DIR"
"""Environment variable overriding the cache folder."""


def is_writable_dir(folder: Path) -> bool:
    """True when `folder` exists (or can be created) and a file can be written in it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".probe-"):
            pass
        return True
    except OSError:
        return False


def _xdg_base(variable: str, default: str) -> Path:
    """`$variable` when it is an absolute path (the XDG rule: relative ones are ignored), else
    `~/default`."""
    value = os.environ.get(variable, "")
    return Path(value) if value and Path(value).is_absolute() else Path.home() / default


def cache_root() -> Path:
    """The user cache folder: $AUTOTRACK_CACHE_DIR, else $XDG_CACHE_HOME/autotrack, else
    ~/.cache/autotrack; a temporary folder when none of them is writable."""
    configured = os.environ.get(CACHE_ENV)
    if configured:
        candidates = [Path(configured).expanduser()]
    else:
        candidates = [_xdg_base("XDG_CACHE_HOME", ".cache") / TOOL_FOLDER]
    candidates.append(Path(tempfile.gettempdir()) / f"autotrack-cache-{os.getuid()}")
    for folder in candidates:
        if is_writable_dir(folder):
            return folder
    return candidates[-1]


def data_root() -> Path:
    """The user data folder: $XDG_DATA_HOME/autotrack, else ~/.local/share/autotrack (not
    created here)."""
    return _xdg_base("XDG_DATA_HOME", ".local/share") / TOOL_FOLDER


def default_sessions_dir() -> Path:
    """Where the app records sessions and keeps uploads unless told otherwise (`--sessions`)."""
    return data_root() / "sessions"
