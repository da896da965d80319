"""Returning freed C-heap pages to the OS between episodes.

A world (its map, rasteriser buffers, SUMO's network) is freed when its env closes, but glibc
keeps freed pages in its arenas, one per thread that allocated, for reuse. A long evaluation
that opens worlds from worker threads therefore grows in RSS though nothing is held: most of
the 9 % that 10,000 soak episodes grew before this (docs/robustness.md). `release_free_heap()` runs glibc's
`malloc_trim(0)` (about a millisecond) so the footprint follows what is really held; on other C
libraries it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
from typing import Any


@functools.cache
def _malloc_trim() -> Any:
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):  # not glibc (musl, macOS, Windows)
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_free_heap() -> bool:
    """glibc's malloc_trim(0); False where there is none."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
