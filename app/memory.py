"""Giving memory back to the system when a tab closes.

A closed tab's trackers, maps and frames are freed by Python, but glibc keeps the freed heap
in its arenas, so the server's RSS would stay at its peak after a long session. `malloc_trim`
returns it.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
from functools import cache


@cache
def _libc() -> ctypes.CDLL | None:
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6")
    except OSError:
        return None
    return libc if hasattr(libc, "malloc_trim") else None


def release_freed_memory() -> bool:
    """Collect unreachable objects, then ask glibc to return free heap pages to the system
    (`malloc_trim(0)`). False where the C library has no malloc_trim (not glibc)."""
    gc.collect()
    libc = _libc()
    if libc is None:
        return False
    libc.malloc_trim(0)
    return True
