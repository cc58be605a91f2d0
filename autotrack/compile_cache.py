"""Where compiled kernels are kept between processes, so start-up stays short.

- numba kernels are compiled with `cache=True`. numba keys a cached kernel on its own source
  file only: a kernel that calls a kernel of another module keeps the callee's old code after
  that module changes (an upgrade, an edit), and runs it silently. So `configure_numba_cache`
  points numba at a folder named by a digest of the package's sources and numba's version,
  `kernels-<digest>` inside `$NUMBA_CACHE_DIR` when that is set and writable, otherwise inside
  the tool's cache folder (`autotrack.userdirs.cache_root() / "numba"`; never beside the
  source, which may be read-only): any change to any module, or another numba, gives a new
  folder and a fresh compile (~10 s once); the
  second process of the same sources loads instead of recompiling. The three newest such
  folders are kept, and any other that nothing wrote to in the last hour is removed.
  $NUMBA_CACHE_DIR is process-wide: another library's numba kernels in the same process are
  cached in that folder too (numba has no per-package setting).

- arrays that take tens of milliseconds to compute and never change for a given source and
  numpy (the 'lab11' colour table) are kept as `.npy` files by `cached_array`.

This module must stay importable without numba (it runs before numba is imported).
"""

from __future__ import annotations

import hashlib
import io
import os
import shutil
import sys
import time
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING

from autotrack.userdirs import cache_root, is_writable_dir

if TYPE_CHECKING:
    import numpy as np

PACKAGE_DIR = Path(__file__).resolve().parent

KERNEL_FOLDER_PREFIX = "kernels-"
KEPT_KERNEL_FOLDERS = 3
STALE_SECONDS = 3600.0


def source_digest(package_dir: Path = PACKAGE_DIR) -> str:
    """16 hex digits of sha256 over numba's version and every module of the package (relative
    path and bytes): environments with other numba versions keep their own builds."""
    digest = hashlib.sha256()
    try:
        digest.update(metadata.version("numba").encode())
    except metadata.PackageNotFoundError:
        digest.update(b"no numba")
    for path in sorted(package_dir.rglob("*.py")):
        digest.update(path.relative_to(package_dir).as_posix().encode())
        digest.update(b"\0")
        try:
            digest.update(path.read_bytes())
        except OSError:
            digest.update(b"unreadable")
    return digest.hexdigest()[:16]


def configure_numba_cache(package_dir: Path = PACKAGE_DIR) -> Path:
    """Point numba's `cache=True` kernels at `kernels-<source digest>` in a writable folder (see
    the module's docstring); returns that folder and sets $NUMBA_CACHE_DIR (and numba's config,
    if numba is already imported), which child processes inherit as it is."""
    name = KERNEL_FOLDER_PREFIX + source_digest(package_dir)
    configured = os.environ.get("NUMBA_CACHE_DIR")
    if configured and Path(configured).name == name and is_writable_dir(Path(configured)):
        return Path(configured)  # a parent process of the same sources chose it
    if configured and is_writable_dir(Path(configured)):
        base = Path(configured)
    else:
        base = cache_root() / "numba"
    folder = base / name
    folder.mkdir(parents=True, exist_ok=True)
    _drop_old_kernel_folders(base, keep=folder)
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    numba_config = sys.modules.get("numba.core.config")
    if numba_config is not None:
        numba_config.CACHE_DIR = str(folder)
    return folder


def _drop_old_kernel_folders(base: Path, keep: Path) -> None:
    """Remove the kernel folders of earlier sources beyond the newest `KEPT_KERNEL_FOLDERS`
    (this one included) that nothing has written to for an hour (a process still running
    on older sources may compile into its folder)."""
    try:
        folders = [p for p in base.glob(KERNEL_FOLDER_PREFIX + "*") if p.is_dir() and p != keep]
        modified = {folder: folder.stat().st_mtime for folder in folders}
    except OSError:
        return
    folders.sort(key=modified.__getitem__, reverse=True)
    for folder in folders[KEPT_KERNEL_FOLDERS - 1 :]:
        if modified[folder] < time.time() - STALE_SECONDS:
            shutil.rmtree(folder, ignore_errors=True)


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
