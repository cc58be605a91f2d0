"""Checks every command makes before any work starts: output paths and numeric options.

A run that tracks every frame and then cannot write its result loses it all, so an output path
that cannot be written (a folder, a read-only place, a missing parent that cannot be made) or
that would overwrite a file without `--force` ends the command at once, in one line.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from autotrack.errors import InputError


def _nearest_existing(path: Path) -> Path:
    """`path` or its closest ancestor that exists."""
    current = path.absolute()
    while not current.exists() and current != current.parent:
        current = current.parent
    return current


def check_output_file(path: Path | None, option: str, *, force: bool) -> None:
    """`path` can be written as a file: not a folder, not an existing file unless `force`,
    and its folder exists or can be made, writable."""
    if path is None:
        return
    if path.is_dir():
        raise InputError(f"{option} {path} is a folder; give a file name")
    if path.exists() or path.is_symlink():
        if not force:
            raise InputError(f"{option} {path} exists; pass --force to replace it")
        if not os.access(path, os.W_OK):
            raise InputError(f"{option} {path} cannot be written (permission denied)")
    check_output_folder(path.parent, option)


def check_output_folder(folder: Path, option: str) -> None:
    """`folder` exists as a writable folder, or can be made inside one."""
    existing = _nearest_existing(folder)
    if not existing.is_dir():
        raise InputError(f"{option}: {existing} is not a folder, so {folder} cannot be made")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"{option}: cannot write into {existing} (permission denied)")


def finite(value: float | None, option: str, *, low: float = -math.inf, high: float = math.inf):
    """`value` unless it is NaN, infinite or outside (low, high]; None passes."""
    if value is None:
        return None
    if not math.isfinite(value) or not low < value <= high:
        bounds = f" in ({low:g}, {high:g}]" if math.isfinite(high) else f" above {low:g}"
        raise InputError(f"{option} must be a finite number{bounds}, got {value!r}")
    return value
