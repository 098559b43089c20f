"""Memory a fit needs, estimated before fitting so work that cannot fit is refused at once with a clear
message instead of running for minutes into the memory limit."""

from __future__ import annotations

from ..errors import LimitError
from .options import FitTolerances

FIT_BYTES_PER_FRAME_VERTEX = 480
"""Peak memory of an in-memory fit grows with frames x vertices: measured 205-229 bytes each (icospheres of
10k and 41k vertices, 100-400 frames, peak RSS over the start) with loose targets, and up to 390 above
FIT_BASE_BYTES with tight ones (benchmarks/compression_peers.py, 2026-11-26: samba at rel-RMS 1e-3, 1,161 MiB
peak for 175 frames x 9,971 vertices; pdance 341, elephant-gallop 238), rounded up for headroom."""
WINDOWED_BYTES_PER_FRAME_VERTEX = 64
"""A fit in windows of frames (pdeanim.fit.windowed) keeps, per frame-vertex, the poses (12 bytes), every
frame's projected tracks (float32: 16 bytes per item, up to one item per vertex coordinate of three-point
curves) and the clip's integer codes and tracks (4 + 4 bytes per knot coefficient): at most about 60."""
WINDOWED_WINDOW_BYTES = FIT_BYTES_PER_FRAME_VERTEX
"""... plus, per frame-vertex value of one window, what an in-memory fit of its frames takes (each window
runs the one-piece fit's segment search and rate control)."""
FIT_BASE_BYTES = 512 * 1024**2  # the interpreter, numpy/scipy/numba and the poses themselves at small sizes
PLAN_BYTES_PER_FRAME_VERTEX = 32
"""A fit in window tasks (the service's job queue): the task that plans it reads the poses once, the stored
.npz (compressed float32, at most 12 bytes) and its float32 vertices (12 bytes), and writes the raw frames
from them: 24, rounded up."""
PLAN_CURVE_BYTES_PER_VALUE = 400
"""... and chooses the curves on sampled frames (pdeanim.fit.windowed.curve_frames: about CURVE_VALUES
frame-vertex values at most; an in-memory space fit takes a few hundred bytes each)."""
JOIN_BYTES_PER_FRAME_VERTEX = 16
"""The task that joins the windows' codes into the clip: every window's integer codes and the clip's tracks
(4 + 4 bytes per knot coefficient, 12 coefficients per curve, a curve per few vertices) and the per-frame
report: at most about 12."""


def fit_memory_bytes(n_frames: int, n_vertices: int, tol: FitTolerances | None = None) -> int:
    """Estimated peak memory of fitting (F, V, 3) poses (in windows of frames where the fit would be)."""
    tol = tol or FitTolerances()
    values = int(n_frames) * int(n_vertices)
    if tol.dense_fit and values > tol.window_fit_values:
        return (FIT_BASE_BYTES + WINDOWED_BYTES_PER_FRAME_VERTEX * values
                + WINDOWED_WINDOW_BYTES * min(values, tol.window_values))
    return FIT_BASE_BYTES + FIT_BYTES_PER_FRAME_VERTEX * values


def window_task_memory_bytes(n_frames: int, n_vertices: int, tol: FitTolerances | None = None) -> int:
    """Estimated peak memory of the largest task of a fit in window tasks (plan, one window, or join): what
    each worker needs when the windows of (F, V, 3) poses run as tasks of the job queue."""
    from .windowed import curve_frames

    tol = tol or FitTolerances()
    values = int(n_frames) * int(n_vertices)
    sampled = curve_frames(int(n_frames), int(n_vertices)) * int(n_vertices)
    plan = PLAN_BYTES_PER_FRAME_VERTEX * values + PLAN_CURVE_BYTES_PER_VALUE * sampled
    window = WINDOWED_WINDOW_BYTES * min(values, tol.window_values)
    join = JOIN_BYTES_PER_FRAME_VERTEX * values
    return FIT_BASE_BYTES + max(plan, window, join)


def check_fit_memory(n_frames: int, n_vertices: int, limit_bytes: int, tol: FitTolerances | None = None,
                     tasks: bool = False) -> None:
    """LimitError naming the sizes when the fit's estimate is over ``limit_bytes`` (0: no limit); with
    ``tasks``, the estimate of the largest window task (the fit runs as window tasks)."""
    need = (window_task_memory_bytes(n_frames, n_vertices, tol) if tasks
            else fit_memory_bytes(n_frames, n_vertices, tol))
    if limit_bytes and need > limit_bytes:
        what = "the largest window task of a fit of" if tasks else "fit"
        exc = LimitError(f"estimated memory to {what} {n_frames} frames x {n_vertices} vertices in GiB",
                         round(need / 1024**3, 2), round(limit_bytes / 1024**3, 2),
                         "PDEANIM_JOB_MEMORY_BYTES or PDEANIM_JOB_MEMORY_FRACTION")
        exc.args = (f"{exc}: fit fewer frames or a coarser mesh, or raise the limit",)
        raise exc
