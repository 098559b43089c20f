"""What a failed allocation needed and which limit refused it, so the command line and the worker can turn a
MemoryError into a message naming the memory, the limit and what to change, instead of a traceback."""

from __future__ import annotations

import resource
from pathlib import Path

from .errors import OutOfMemoryError

CGROUP_FILES = (Path("/sys/fs/cgroup/memory.max"), Path("/sys/fs/cgroup/memory/memory.limit_in_bytes"))
"""cgroup v2, then v1: the memory limit of the container the process runs in."""
UNLIMITED_CGROUP = 1 << 60  # cgroup v1 writes a huge number (page-rounded 2^63 - 1) for "no limit"


def gib(n: int) -> str:
    """``n`` bytes as GiB with two decimals: '3.41 GiB'."""
    return f"{n / 1024**3:.2f} GiB"


def allocation_bytes(exc: BaseException) -> int | None:
    """Bytes the failed allocation asked for: numpy's array allocation errors (and OutOfMemoryError) carry
    it; None otherwise."""
    size = getattr(exc, "_total_size", None) or getattr(exc, "needed", None)  # numpy's, or ours re-described
    return int(size) if isinstance(size, int) and size > 0 else None


def allocation_text(exc: BaseException) -> str:
    """'allocating 3.41 GiB (an array of shape (..) float64)' or 'an allocation' when the size is unknown."""
    size = allocation_bytes(exc)
    if size is None:
        return "an allocation"
    shape, dtype = getattr(exc, "shape", None), getattr(exc, "dtype", None)
    what = f" (an array of shape {tuple(shape)} {dtype})" if shape is not None and dtype is not None else ""
    return f"allocating {gib(size)}{what}"


def address_space_limit() -> int | None:
    """This process's address-space limit (RLIMIT_AS, ``ulimit -v``) in bytes, or None if unlimited."""
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    return None if soft == resource.RLIM_INFINITY else int(soft)


def cgroup_memory_limit(files: tuple[Path, ...] = CGROUP_FILES) -> int | None:
    """The memory limit of this process's cgroup (container) in bytes, or None if none is set or readable."""
    for path in files:
        try:
            text = path.read_text().strip()
        except OSError:
            continue
        if text.isdigit() and int(text) < UNLIMITED_CGROUP:
            return int(text)
    return None


def memory_limit() -> tuple[int, str] | None:
    """(bytes, what it is) of the limit in force: the address-space limit, else the cgroup's, else None."""
    limit = address_space_limit()
    if limit is not None:
        return limit, "address-space limit (RLIMIT_AS, ulimit -v)"
    limit = cgroup_memory_limit()
    if limit is not None:
        return limit, "cgroup memory limit (memory.max)"
    return None


def out_of_memory(exc: BaseException, advice: str, limit: tuple[int, str] | None = None) -> OutOfMemoryError:
    """An OutOfMemoryError for the MemoryError ``exc``: what failed, under which limit (``limit`` if given,
    else the one in force), and ``advice`` (the setting or option that would help)."""
    limit = limit if limit is not None else memory_limit()
    where = f"under the {limit[1]} of {gib(limit[0])}" if limit else "with no memory limit set (the " \
        "machine's memory ran out)"
    message = f"out of memory: {allocation_text(exc)} failed {where}; {advice}"
    return OutOfMemoryError(message, allocation_bytes(exc), limit[0] if limit else None)
