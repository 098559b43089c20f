"""A fit in windows of frames as tasks of the job queue, so that any worker on any machine takes a window.

A fit job whose input is fitted in windows (``pdeanim.fit.windowed.windowed_applies``) is claimed as usual;
its attempt plans the fit (curves, rounding, window bounds) and stores the poses once as raw float32 frames,
then :func:`split` moves the job to the state ``waiting`` and enqueues one ``gram`` task per window. Each
task is a row of ``jobs`` (kind ``window``, ``parent_id`` the fit job, ``window_index``, ``phase``) with the
same claim, lease, fencing and retries as any job, so a killed worker's window is retried alone. The finish
of the last task of a phase enqueues the next phase (:func:`task_done`, under a lock of the fit job's row):
all ``gram`` -> one ``space`` (joins the space model) -> one ``encode`` per window -> one ``join``, whose
finish writes the clip row and marks the fit job succeeded. The intermediates live in the blob store under
``windowed/<fit job>/``. A task that fails for good fails its fit job and cancels the other tasks
(:func:`pdeanim_service.store.parents.fail_parent`); cancelling the fit job cancels every task
(``JobQueue.cancel``).
"""

from __future__ import annotations

import logging
import time
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from .blobrefs import hold
from .blobs import BlobStore
from .models import ClipRecord, Job
from .parents import locked as _locked
from .queue import Claimed, JobQueue

log = logging.getLogger("pdeanim.worker")
TASK_KIND = "window"
PLAN_SHARE = 0.05  # of the fit job's progress: planning (the fit job's own attempt)
JOIN_SHARE = 0.2  # the join (the last task builds, compresses and stores the clip: a large share of the job)
WINDOW_SHARE = 1.0 - PLAN_SHARE - JOIN_SHARE  # each window's Gram part and codes, counted as they run


def blob_prefix(job_id: str) -> str:
    """Where the intermediates of fit job ``job_id`` live in the blob store."""
    return f"windowed/{job_id}/"


def frames_key(job_id: str) -> str:
    """The poses of the fit as raw float32 (F, V, 3), read by range per window."""
    return blob_prefix(job_id) + "frames.f32"


def plan_key(job_id: str) -> str:
    """The fit's WindowPlan bytes."""
    return blob_prefix(job_id) + "plan"


def space_key(job_id: str) -> str:
    """The joined SpaceModel bytes."""
    return blob_prefix(job_id) + "space"


def gram_key(job_id: str, index: int) -> str:
    """Window ``index``'s GramPart bytes."""
    return blob_prefix(job_id) + f"gram-{index}"


def codes_key(job_id: str, index: int) -> str:
    """Window ``index``'s WindowCodes bytes."""
    return blob_prefix(job_id) + f"codes-{index}"


def blob_keys(job_id: str, n_windows: int) -> list[str]:
    """Every intermediate blob a fit in ``n_windows`` window tasks may have written."""
    per_window = [k(job_id, i) for i in range(n_windows) for k in (gram_key, codes_key)]
    return [frames_key(job_id), plan_key(job_id), space_key(job_id), *per_window]


def release_blobs(blobs, job_id: str, n_windows: int) -> None:  # noqa: ANN001 - a BlobStore
    """Remove the intermediates of a windowed fit that ended (succeeded, failed, cancelled or deleted)."""
    for key in blob_keys(job_id, n_windows):
        try:
            blobs.delete(key)
        except Exception:  # noqa: BLE001 - an orphan intermediate wastes space but breaks nothing
            log.warning("could not remove intermediate blob %s", key, exc_info=True)


def _task(parent: Job, phase: str, index: int, n_windows: int, max_attempts: int) -> Job:
    """A queued window task of ``parent`` (mesh and poses named too, so deleting them reaches it)."""
    return Job(tenant_id=parent.tenant_id, kind=TASK_KIND, mesh_id=parent.mesh_id, poses_id=parent.poses_id,
               params={"fit_job": parent.id, "phase": phase, "window": index, "windows": n_windows},
               state="queued", max_attempts=max_attempts, run_after=time.time(), progress=0.0,
               stage="queued", result={}, versions={}, attempt=0, failures=0, parent_id=parent.id,
               window_index=index, phase=phase)


def split(queue: JobQueue, job: Claimed, n_windows: int) -> bool:
    """Fenced: the planning attempt of fit ``job`` hands the fit to ``n_windows`` gram tasks and the job
    waits for them (no lease: its tasks hold theirs). False if the attempt no longer owns the job."""
    with queue._write() as session, session.begin():
        parent = session.execute(select(Job).where(Job.id == job.id, Job.attempt == job.attempt,
                                                   Job.state == "running").with_for_update()
                                 ).scalar_one_or_none()
        if parent is None:
            return False
        parent.state, parent.lease_expires, parent.worker_id = "waiting", None, None
        parent.progress = max(float(parent.progress or 0.0), PLAN_SHARE)
        parent.result = {"windows": n_windows, "windows_done": 0}
        parent.stage = f"fit in {n_windows} windows: 0 of {n_windows} summed, 0 encoded"
        for i in range(n_windows):
            session.add(_task(parent, "gram", i, n_windows, queue.policy.max_attempts))
    return True


def _count(session: Session, parent_id: str, phase: str) -> int:
    return session.execute(select(func.count()).select_from(Job).where(
        Job.parent_id == parent_id, Job.phase == phase, Job.state == "succeeded")).scalar_one()


def _fit_progress(session: Session, parent: Job) -> float:
    """The fit job's progress from its tasks' rows: planning done, then each window's Gram part and codes
    (a running task by its own progress), then the join by its progress."""
    W = int(parent.result.get("windows", 0))
    rows = session.execute(select(Job.phase, Job.state, Job.progress).where(Job.parent_id == parent.id)).all()

    def done(phases: tuple[str, ...]) -> float:
        return sum(1.0 if state == "succeeded" else float(p or 0.0) if state == "running" else 0.0
                   for phase, state, p in rows if phase in phases)

    windows = min(done(("gram", "encode")) / max(2 * W, 1), 1.0)
    return PLAN_SHARE + WINDOW_SHARE * windows + JOIN_SHARE * min(done(("join",)), 1.0)


def _raise_progress(session: Session, parent: Job) -> None:
    """Move the fit job's progress up to what its tasks say, never down (a retried task starts again at 0)."""
    parent.progress = max(float(parent.progress or 0.0), _fit_progress(session, parent))


def task_progress(queue: JobQueue, job: Claimed) -> None:
    """A running window task reported progress (its row is written): its fit job's progress follows."""
    with queue._write() as session, session.begin():
        parent = _locked(session, job.parent_id or "")
        if parent is not None and parent.state == "waiting":
            _raise_progress(session, parent)


def _advance(session: Session, parent: Job, task: Job, result: dict[str, Any], max_attempts: int) -> None:
    """After ``task`` succeeded: the fit job's progress (windows summed and encoded) and the next phase."""
    W = int(parent.result.get("windows", 0))
    grams, encoded = _count(session, parent.id, "gram"), _count(session, parent.id, "encode")
    _raise_progress(session, parent)
    parent.stage = f"fit in {W} windows: {grams} of {W} summed, {encoded} encoded"
    parent.result = {**parent.result, "windows_done": encoded}
    if task.phase == "gram" and grams == W:
        session.add(_task(parent, "space", 0, W, max_attempts))
    elif task.phase == "space":
        session.add_all([_task(parent, "encode", i, W, max_attempts) for i in range(W)])
    elif task.phase == "encode" and encoded == W:
        session.add(_task(parent, "join", 0, W, max_attempts))
        parent.stage = f"fit in {W} windows: joining the clip"
    elif task.phase == "join":
        c = result["clip"]
        clip = ClipRecord(tenant_id=parent.tenant_id, mesh_id=parent.mesh_id, poses_id=parent.poses_id,
                          job_id=parent.id, kind=c["kind"], topology_key=c["topology_key"],
                          coefficients_key=c["coefficients_key"], topology_id=c["topology_id"],
                          report=c.get("report", {}))
        session.add(clip)
        session.flush()
        parent.state, parent.progress, parent.stage = "succeeded", 1.0, "done"
        parent.finished_at = time.time()
        parent.result = {"clip_id": clip.id, "windows": W, "windows_done": W}


def task_done(queue: JobQueue, job: Claimed, result: dict[str, Any], blobs: BlobStore) -> str | None:
    """Fenced success of a window task: the task succeeds, its fit job advances (next phase enqueued once
    the phase is complete; the join writes the clip, its blobs checked under their locks: BlobGone if a
    concurrent delete took one). Returns the fit job's state, or None if the attempt no longer owns the task
    or the fit job no longer waits for it (cancelled, failed, deleted)."""
    with queue._write() as session, session.begin():
        parent = _locked(session, job.parent_id or "")  # the fit job first: every writer locks it first
        task = session.execute(select(Job).where(Job.id == job.id, Job.attempt == job.attempt,
                                                 Job.state == "running").with_for_update()
                               ).scalar_one_or_none()
        if task is None or parent is None or parent.state != "waiting":
            return None
        if "clip" in result:  # the join: the clip row will name these
            hold(session, blobs, dict.fromkeys([result["clip"]["topology_key"],
                                                result["clip"]["coefficients_key"]]))
        task.state, task.progress, task.stage, task.finished_at = "succeeded", 1.0, "done", time.time()
        task.lease_expires, task.result = None, {k: v for k, v in result.items() if k != "clip"}
        session.flush()
        _advance(session, parent, task, result, queue.policy.max_attempts)
        return parent.state
