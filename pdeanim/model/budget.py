"""Memory a fit needs, estimated before fitting so work that cannot fit is refused at once with a clear
message instead of running for minutes into the memory limit."""

from __future__ import annotations

from ..errors import LimitError

FIT_BYTES_PER_FRAME_VERTEX = 480
"""Peak memory of ``fit_poses`` grows with frames x vertices: measured 205-229 bytes each (icospheres of 10k
and 41k vertices, 100-400 frames, peak RSS over the start) with loose targets, and up to 390 above
FIT_BASE_BYTES with tight ones (benchmarks/compression_peers.py, 2026-11-26: samba at rel-RMS 1e-3, 1,161 MiB
peak for 175 frames x 9,971 vertices, 455 while the encoder held all its knot-basis candidates at once;
pdance 341, elephant-gallop 238), rounded up for headroom."""
FIT_BASE_BYTES = 512 * 1024**2  # the interpreter, numpy/scipy/numba and the poses themselves at small sizes


def fit_memory_bytes(n_frames: int, n_vertices: int) -> int:
    """Estimated peak memory of fitting (F, V, 3) poses."""
    return FIT_BASE_BYTES + FIT_BYTES_PER_FRAME_VERTEX * int(n_frames) * int(n_vertices)


def check_fit_memory(n_frames: int, n_vertices: int, limit_bytes: int) -> None:
    """LimitError naming the sizes when the fit's estimate is over ``limit_bytes`` (0: no limit)."""
    need = fit_memory_bytes(n_frames, n_vertices)
    if limit_bytes and need > limit_bytes:
        exc = LimitError(f"estimated memory to fit {n_frames} frames x {n_vertices} vertices in GiB",
                         round(need / 1024**3, 2), round(limit_bytes / 1024**3, 2),
                         "PDEANIM_JOB_MEMORY_BYTES or PDEANIM_JOB_MEMORY_FRACTION")
        exc.args = (f"{exc}: fit fewer frames or a coarser mesh, or raise the limit",)
        raise exc
