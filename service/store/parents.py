"""The fit job above a window task (pdeanim_service.store.windows): the order in which writers lock the two
rows, and
failing the fit when a task fails for good. Below both the queue and the window tasks, so that neither imports
the other."""

from __future__ import annotations

import time

from sqlalchemy import select, update
from sqlalchemy.orm import Session

from .models import Job

# waiting: a fit whose window tasks run (pdeanim_service.store.windows)
ACTIVE = ("queued", "running", "waiting")


def locked(session: Session, job_id: str) -> Job | None:
    return session.execute(select(Job).where(Job.id == job_id).with_for_update()).scalar_one_or_none()


def lock_parent_first(session: Session, job_id: str) -> None:
    """Lock the fit job of a window task before the task itself (the order every writer keeps, so that
    concurrent finishes, failures and cancels of a fit's tasks never deadlock on PostgreSQL)."""
    parent_id = session.execute(select(Job.parent_id).where(Job.id == job_id)).scalar_one_or_none()
    if parent_id:
        locked(session, parent_id)


def fail_parent(session: Session, task: Job) -> None:
    """A window task failed for good: its fit job fails with the task's reason and the other tasks are
    cancelled (their workers stop at the next heartbeat)."""
    parent = session.get(Job, task.parent_id)
    if parent is None or parent.state not in ACTIVE:
        return
    where = "the join" if task.phase in ("space", "join") else f"window {task.window_index} ({task.phase})"
    parent.state, parent.stage, parent.finished_at = "failed", "failed", time.time()
    parent.error, parent.error_code = f"{where} of the fit failed: {task.error}"[:4000], task.error_code
    session.execute(update(Job).where(Job.parent_id == parent.id, Job.id != task.id, Job.state.in_(ACTIVE))
                    .values(state="cancelled", stage="cancelled: another window task failed",
                            lease_expires=None, finished_at=time.time())
                    .execution_options(synchronize_session=False))
