"""Keep freed memory in the API process: large response bodies (a 20k-vertex frame GLB is 720 KB) otherwise
get fresh pages from the kernel on every request, and those page faults cost more than computing the frame."""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc mallopt parameters
MMAP_THRESHOLD = 32 * 1024 * 1024  # glibc's maximum: allocations below it come from the reusable heap
TRIM_THRESHOLD = 1024 * 1024 * 1024  # give heap memory back to the kernel only past 1 GiB free at the top


def keep_freed_memory() -> bool:
    """Tell glibc's malloc to serve allocations up to 32 MiB from its heap and keep freed memory for
    reuse (measured here: a 720 KB allocate-fill-copy went from 0.77 ms to 0.025 ms). The process keeps
    its peak heap, which the frame and clip caches bound. Returns False where it does not apply."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
