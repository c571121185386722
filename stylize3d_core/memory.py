"""Process-wide memory settings of the viewer, the command line and the benchmarks' fresh processes.

Library code never calls :func:`keep_freed_memory` by itself (it changes the whole process's
allocator); the programs that own their process do, before their first large allocation.
"""

from __future__ import annotations

import sys

KEEP_FREED_BYTES = 1 << 30
"""glibc malloc's mmap and trim thresholds set by :func:`keep_freed_memory`."""


def keep_freed_memory() -> bool:
    """Make glibc keep freed memory for reuse instead of returning it to the system (``mallopt``).

    Every frame allocates and frees tens of megabytes of tensors (a 768x512 frame's 35 rasterized
    channels are 55 MB); by default glibc serves each with a fresh ``mmap`` whose pages the kernel
    zeroes on first touch, which took ~15 % of the compute worker's CPU (``perf``) and made an
    allocate-fill loop 2.5-3x slower than with the memory kept (measured under load). The price:
    the process keeps its peak memory. False where this is not glibc (nothing changes)."""
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("c")
    if not sys.platform.startswith("linux") or not name:
        return False
    try:
        libc = ctypes.CDLL(name)
        m_trim_threshold, m_mmap_threshold = -1, -3
        return bool(libc.mallopt(m_mmap_threshold, KEEP_FREED_BYTES)) and bool(
            libc.mallopt(m_trim_threshold, KEEP_FREED_BYTES))
    except (OSError, AttributeError):  # not glibc
        return False


__all__ = ["KEEP_FREED_BYTES", "keep_freed_memory"]
