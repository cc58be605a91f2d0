"""Where compiled kernels are kept between processes, so start-up stays short.

- numba kernels are compiled with `cache=True`: numba writes them next to the source
  (`autotrack/__pycache__`) when that folder is writable. For a read-only install (a system
  site-packages, a container image) `configure_numba_cache` points numba at a user cache
  folder instead (`$NUMBA_CACHE_DIR` when it is set and writable, otherwise
  `cache_root() / "numba"`), so the second process loads instead of recompiling (~2 s).

- arrays that take tens of milliseconds to compute and never change for a given source and
  numpy (the 'lab11' colour table) are kept as `.npy` files by `cached_array`.

This module must stay importable without numba (it runs before numba is imported).
"""

from __future__ import annotations

import hashlib
import io
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

CACHE_ENV = "AUTOTRACK_CACHE_DIR"
"""Environment variable overriding the cache folder."""

PACKAGE_DIR = Path(__file__).resolve().parent


def is_writable_dir(folder: Path) -> bool:
    """True when `folder` exists (or can be created) and a file can be written in it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".probe-"):
            pass
        return True
    except OSError:
        return False


def cache_root() -> Path:
    """The user cache folder: $AUTOTRACK_CACHE_DIR, else $XDG_CACHE_HOME/autotrack, else
    ~/.cache/autotrack; a temporary folder when none of them is writable."""
    configured = os.environ.get(CACHE_ENV)
    if configured:
        candidates = [Path(configured).expanduser()]
    else:
        base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        candidates = [Path(base).expanduser() / "autotrack"]
    candidates.append(Path(tempfile.gettempdir()) / f"autotrack-cache-{os.getuid()}")
    for folder in candidates:
        if is_writable_dir(folder):
            return folder
    return candidates[-1]


def configure_numba_cache(package_dir: Path = PACKAGE_DIR) -> Path:
    """Make sure numba's `cache=True` kernels land in a writable folder; returns that folder.

    Keeps numba's default (beside the source) when it is writable and $NUMBA_CACHE_DIR is not
    set; otherwise sets $NUMBA_CACHE_DIR (and numba's config, if numba is already imported).
    """
    configured = os.environ.get("NUMBA_CACHE_DIR")
    if configured and is_writable_dir(Path(configured)):
        return Path(configured)
    if not configured and is_writable_dir(package_dir / "__pycache__"):
        return package_dir / "__pycache__"
    folder = cache_root() / "numba"
    folder.mkdir(parents=True, exist_ok=True)
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    numba_config = sys.modules.get("numba.core.config")
    if numba_config is not None:
        numba_config.CACHE_DIR = str(folder)
    return folder


def cached_array(name: str, key: str, build: Callable[[], np.ndarray]) -> np.ndarray:
    """`build()`'s array, kept between processes in `cache_root() / "arrays"`.

    `key` names everything the array depends on (e.g. a digest of the source that builds it
    and numpy's version); the file is `{name}-{sha256(key)[:16]}.npy`. A missing, unreadable
    or corrupt file is rebuilt; an unwritable cache only costs the rebuild next time.
    """
    import numpy as np

    from autotrack.io.atomic import write_bytes

    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    path = cache_root() / "arrays" / f"{name}-{digest}.npy"
    try:
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError):
        pass
    array = build()
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes(path, buffer.getvalue())
    except OSError:
        pass
    return array
