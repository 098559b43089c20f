"""The steps of a fit in window tasks, run in the job's child process like any stage
(pdeanim_service.store.windows
says how the queue chains them): the fit job's attempt plans the fit and stores the raw frames; each task
then reads the plan, its window's frames (a ranged read of the raw float32 poses) or the intermediates of
the phase before it, and stores its own under ``windowed/<fit job>/``. Every step is deterministic, so the
clip is byte-identical to the in-process windowed fit of the same poses and options."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pdeanim.fit import windowed
from pdeanim.progress import Progress, sub_progress
from pdeanim_service.settings import Settings
from pdeanim_service.store import windows as keys
from pdeanim_service.store.blobs import BlobStore

from .clipstore import store_clip

FRAME_BYTES = 12  # float32 x, y, z per vertex
READ_SHARE, STORE_AT = 0.2, 0.9  # the join's progress: windows' codes read by 0.2, joined by 0.9, then stored


def plan_fit(job_id: str, poses, options, tol, blobs: BlobStore, progress: Progress,  # noqa: ANN001
             workdir: Path) -> dict:
    """The fit job's own attempt: plan the windows, store the plan and the frames as raw float32 (written
    through a file, no second copy in memory); the worker then enqueues the window tasks. Its progress is
    the planning share of the fit job's (the window tasks and the join move it on from there)."""
    progress = sub_progress(progress, 0.0, keys.PLAN_SHARE)
    plan = windowed.plan_windows(poses, options, tol, sub_progress(progress, 0.0, 0.8))
    progress(0.85, f"fit: store {poses.n_frames} frames for {plan.n_windows} window tasks")
    raw = workdir / "frames.f32"
    workdir.mkdir(parents=True, exist_ok=True)
    np.ascontiguousarray(poses.vertices, np.float32).tofile(raw)
    blobs.put_file(raw, key=keys.frames_key(job_id))
    raw.unlink()
    blobs.put(plan.to_bytes(), key=keys.plan_key(job_id))
    progress(1.0, f"fit: {plan.n_windows} window tasks")
    return {"windowed": {"windows": plan.n_windows, "frames": poses.n_frames, "vertices": poses.n_vertices}}


def plan_fit_streamed(job_id: str, blob_key: str, limits, options, tol, blobs: BlobStore,  # noqa: ANN001
                      progress: Progress, workdir: Path) -> dict | None:
    """:func:`plan_fit` without the poses in memory: the stored POSES.npz is copied to the work directory,
    its vertices inflated straight into the raw float32 frames file that the window tasks read
    (:func:`pdeanim.poses.load_poses_npz_mapped`), the plan made on that file's mapping (the curves read only
    their sampled frames) and the file stored as it is: the same plan and frames, bit for bit. None where the
    vertices cannot be streamed (one frame, Fortran order): the caller then loads the poses."""
    from pdeanim.npzread import release_pages
    from pdeanim.poses import load_poses_npz_mapped

    progress = sub_progress(progress, 0.0, keys.PLAN_SHARE)
    workdir.mkdir(parents=True, exist_ok=True)
    npz, raw = workdir / "poses.npz", workdir / "frames.f32"
    try:
        blobs.get_file(blob_key, npz)
        poses = load_poses_npz_mapped(npz, limits, into=raw)
        npz.unlink()
        if poses is None:
            return None
        plan = windowed.plan_windows(poses, options, tol, sub_progress(progress, 0.0, 0.8))
        release_pages(poses.vertices)
        progress(0.85, f"fit: store {poses.n_frames} frames for {plan.n_windows} window tasks")
        blobs.put_file(raw, key=keys.frames_key(job_id))
        blobs.put(plan.to_bytes(), key=keys.plan_key(job_id))
    finally:
        npz.unlink(missing_ok=True)
        raw.unlink(missing_ok=True)
    progress(1.0, f"fit: {plan.n_windows} window tasks")
    return {"windowed": {"windows": plan.n_windows, "frames": poses.n_frames, "vertices": poses.n_vertices}}


def window_frames(blobs: BlobStore, fit_job: str, plan: windowed.WindowPlan, index: int) -> np.ndarray:
    """(w, V, 3) float32 frames of window ``index``: a ranged read of the stored raw poses."""
    f0, f1 = plan.window(index)
    V = plan.layout.rest.shape[0]
    data = blobs.get_range(keys.frames_key(fit_job), f0 * V * FRAME_BYTES, (f1 - f0) * V * FRAME_BYTES)
    if len(data) != (f1 - f0) * V * FRAME_BYTES:
        raise RuntimeError(f"the stored frames of {fit_job} end before window {index} ({f0}:{f1})")
    return np.frombuffer(data, np.float32).reshape(f1 - f0, V, 3)


def _space(blobs: BlobStore, fit_job: str) -> windowed.SpaceModel:
    return windowed.SpaceModel.from_bytes(blobs.get(keys.space_key(fit_job)))


def run_window(job: dict, blobs: BlobStore, settings: Settings, progress: Progress, workdir: Path,
               partial=None) -> dict:  # noqa: ANN001
    """One window task: ``gram`` (window i's Gram part), ``space`` (the joined space model), ``encode``
    (window i's codes) or ``join`` (the clip, stored; its row is written with the task's success)."""
    p = job["params"]
    fit_job, phase, index, W = p["fit_job"], p["phase"], int(p["window"]), int(p["windows"])
    plan = windowed.WindowPlan.from_bytes(blobs.get(keys.plan_key(fit_job)))
    progress(0.0, f"{phase} {index + 1}/{W}" if phase in ("gram", "encode") else phase)
    if phase == "gram":
        part = windowed.gram_window(plan, window_frames(blobs, fit_job, plan, index), index)
        blobs.put(part.to_bytes(), key=keys.gram_key(fit_job, index))
    elif phase == "space":
        parts = (windowed.GramPart.from_bytes(blobs.get(keys.gram_key(fit_job, i))) for i in range(W))
        blobs.put(windowed.join_space(plan, parts).to_bytes(), key=keys.space_key(fit_job))
    elif phase == "encode":
        model = windowed.WindowModel(plan, _space(blobs, fit_job))
        codes = windowed.encode_window(model, window_frames(blobs, fit_job, plan, index), index, progress)
        blobs.put(codes.to_bytes(), key=keys.codes_key(fit_job, index))
    elif phase == "join":
        return {"clip": _join(plan, fit_job, W, blobs, progress)}
    else:
        raise ValueError(f"unknown window task phase {phase!r}")
    return {"phase": phase, "window": index}


def _join(plan: windowed.WindowPlan, fit_job: str, W: int, blobs: BlobStore, progress: Progress) -> dict:
    """The clip of every window's codes, stored (a missed target fails the fit unless ``best_effort``);
    progress in steps: each window's codes read, the join, the store."""
    from pdeanim.errors import TargetNotMetError
    from pdeanim.fit import target_shortfall

    codes = []
    for i in range(W):
        codes.append(windowed.WindowCodes.from_bytes(blobs.get(keys.codes_key(fit_job, i))))
        progress(READ_SHARE * (i + 1) / W, f"join: read the codes of window {i + 1} of {W}")
    parts = windowed.join_clip(plan, _space(blobs, fit_job), codes)
    progress(STORE_AT, "join: store the clip")
    parts.report["window_tasks"] = True
    shortfall = target_shortfall(parts.report)
    if shortfall and not plan.options.best_effort:
        raise TargetNotMetError(
            f"{shortfall} (ask for best_effort: true in the fit options to keep the clip)")
    return store_clip(parts, blobs, plan.n_frames, plan.layout.rest.shape[0])
