"""One BLAS thread in the API process. Frames are computed concurrently on the thread pool, and each frame's
evaluation makes small matrix products; OpenBLAS's own worker threads then fight the other requests' calls
(spinning and locking): measured here, 6-8 ms of CPU per 20k-vertex frame from 4-16 threads against 0.4 ms
with one BLAS thread. A server gets its parallelism from concurrent requests and worker processes instead."""

from __future__ import annotations

import ctypes
import logging
from pathlib import Path

log = logging.getLogger("pdeanim.api")

# OpenBLAS builds name the setter with a prefix (scipy-openblas wheels: "scipy_") and a suffix (64-bit
# integer interface: "64_"); numpy's and scipy's wheels each bundle their own library.
_SETTERS = [f"{prefix}openblas_set_num_threads{suffix}"
            for prefix in ("", "scipy_") for suffix in ("", "64_")]


def _loaded_openblas() -> list[str]:
    """Paths of the OpenBLAS libraries mapped into this process (Linux: /proc/self/maps), or []."""
    try:
        lines = Path("/proc/self/maps").read_text().splitlines()
    except OSError:
        return []
    paths = {line.split(maxsplit=5)[-1] for line in lines if line.count(" ") >= 5}
    return sorted(p for p in paths if p.startswith("/") and "openblas" in Path(p).name.lower())


def single_threaded_blas() -> int:
    """Limit every OpenBLAS loaded by numpy and scipy to one thread in this process; returns how many
    libraries were limited (0 where none is found, e.g. another BLAS or no /proc: nothing changes)."""
    import numpy  # noqa: F401 - loads numpy's BLAS

    try:
        import scipy.linalg  # noqa: F401 - loads scipy's BLAS (clip loading and exports use scipy)
    except ImportError:  # pragma: no cover - scipy is a dependency
        pass
    limited = 0
    for path in _loaded_openblas():
        try:
            lib = ctypes.CDLL(path)  # already loaded: the same handle, nothing is loaded twice
        except OSError:
            continue
        for name in _SETTERS:
            setter = getattr(lib, name, None)
            if setter is not None:
                setter.argtypes, setter.restype = [ctypes.c_int], None
                setter(1)
                limited += 1
                break
    log.debug("BLAS limited to one thread in %d librar(y/ies)", limited)
    return limited
