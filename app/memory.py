"""Giving memory back to the system when a tab closes.

A closed tab's trackers, maps and frames are freed by Python, but glibc keeps the freed heap
in its arenas, so the server's RSS would stay at its peak after a long session. `malloc_trim`
returns it. glibc also gives each new thread a heap (arena) of its own, up to eight per core;
every tab's worker, tracker and websocket threads leave pages scattered over them, which
`malloc_trim` cannot give back while any live block sits in the page. The server therefore
caps the arenas (`limit_malloc_arenas`) before it starts its threads.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os
from functools import cache

M_ARENA_MAX = -8
"""glibc's `mallopt` parameter for the most arenas the allocator creates (malloc.h)."""
SERVER_ARENAS = 2
"""Arenas for the app's server: one per core of the small machines it runs on; threads beyond
that share them (their allocations are brief next to tracking a frame)."""


@cache
def _libc() -> ctypes.CDLL | None:
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6")
    except OSError:
        return None
    return libc if hasattr(libc, "malloc_trim") and hasattr(libc, "mallopt") else None


def limit_malloc_arenas(arenas: int = SERVER_ARENAS) -> bool:
    """Cap glibc's malloc arenas for the threads this process starts from now on (call it
    before starting them). A `MALLOC_ARENA_MAX` in the environment is the user's choice and is
    left as it is. False where nothing was changed (that variable set, or not glibc)."""
    if arenas < 1:
        raise ValueError(f"arenas must be at least 1, got {arenas}")
    libc = _libc()
    if libc is None or "MALLOC_ARENA_MAX" in os.environ:
        return False
    return bool(libc.mallopt(M_ARENA_MAX, arenas))


def release_freed_memory() -> bool:
    """Collect unreachable objects, then ask glibc to return free heap pages to the system
    (`malloc_trim(0)`). False where the C library has no malloc_trim (not glibc)."""
    gc.collect()
    libc = _libc()
    if libc is None:
        return False
    libc.malloc_trim(0)
    return True
