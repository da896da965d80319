"""`release_free_heap` (drivehierarchy._heap): freed heap pages go back to the OS on glibc."""

from __future__ import annotations

import platform
from pathlib import Path

import pytest

from drivehierarchy._heap import release_free_heap


def _rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise AssertionError("no VmRSS")


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="glibc only")
def test_freed_heap_pages_return_to_the_os() -> None:
    # 64 KiB blocks stay below glibc's mmap threshold, so they come from the heap; the last one is
    # kept, so free() alone cannot trim the heap's top and the ~190 MB stay resident until trimmed.
    blocks = [bytearray(b"x" * (64 * 1024)) for _ in range(3000)]
    keep = bytearray(b"y" * (64 * 1024))
    del blocks[:]
    held = _rss_mb()
    assert release_free_heap() is True
    after = _rss_mb()
    assert held - after > 100.0, (held, after)
    assert keep[0] == ord("y")
