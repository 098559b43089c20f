"""The job queue on the metadata database: enqueue, atomic claim, lease heartbeat, reaper, fenced finish.

Every claim increments ``jobs.attempt``, the fencing token of that attempt; every later write of the
attempt (progress, heartbeat, success, failure, release) is an ``UPDATE ... WHERE id = :id AND attempt =
:attempt AND state = 'running'``, so a worker whose lease expired and was reaped cannot overwrite the
newer attempt. PostgreSQL claims with ``FOR UPDATE SKIP LOCKED``; SQLite with ``BEGIN IMMEDIATE`` (WAL).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sqlalchemy import Engine, case, select, update
from sqlalchemy.orm import Session, sessionmaker

from .models import Job
from .parents import ACTIVE, fail_parent, lock_parent_first

STATES = ("queued", "running", "waiting", "succeeded", "failed", "cancelled")
FINAL = ("succeeded", "failed", "cancelled")


@dataclass(frozen=True)
class QueuePolicy:
    """Lease length and retry policy (from the settings)."""

    lease_seconds: float = 30.0
    max_attempts: int = 3
    backoff_seconds: float = 2.0
    backoff_max_seconds: float = 300.0

    def backoff(self, failures: int) -> float:
        """Delay before the retry that follows ``failures`` failed attempts (exponential, capped)."""
        return min(self.backoff_seconds * 2.0 ** max(failures - 1, 0), self.backoff_max_seconds)


@dataclass(frozen=True)
class Claimed:
    """What a worker needs to run one attempt of a job."""

    id: str
    kind: str
    attempt: int
    tenant_id: str
    mesh_id: str | None
    poses_id: str | None
    params: dict[str, Any]
    parent_id: str | None = None  # a window task's fit job (pdeanim_service.store.windows)
    phase: str | None = None
    window_index: int | None = None


class JobQueue:
    """Queue operations on one engine; each method runs its own short transaction."""

    def __init__(self, engine: Engine, policy: QueuePolicy):
        self.engine, self.policy = engine, policy
        self.postgres = engine.dialect.name == "postgresql"
        self._write = sessionmaker(engine.execution_options(immediate=True), expire_on_commit=False)

    def enqueue(self, session: Session, *, tenant_id: str, kind: str, params: dict[str, Any],
                mesh_id: str | None = None, poses_id: str | None = None) -> Job:
        """Add a queued job to ``session`` (the caller commits, together with its other writes)."""
        job = Job(tenant_id=tenant_id, kind=kind, params=params, mesh_id=mesh_id, poses_id=poses_id,
                  state="queued", max_attempts=self.policy.max_attempts, run_after=time.time(),
                  progress=0.0, stage="queued", result={}, versions={}, attempt=0, failures=0)
        session.add(job)
        return job

    def claim(self, worker_id: str, versions: dict[str, Any] | None = None) -> Claimed | None:
        """Atomically move the oldest due queued job to running under a new lease; None if none is due."""
        now = time.time()
        pick = (select(Job.id).where(Job.state == "queued", Job.run_after <= now)
                .order_by(Job.run_after, Job.created_at).limit(1))
        if self.postgres:
            pick = pick.with_for_update(skip_locked=True)
        stmt = (
            update(Job)
            .where(Job.id == pick.scalar_subquery())
            .values(
                state="running",
                attempt=Job.attempt + 1,
                worker_id=worker_id,
                lease_expires=now + self.policy.lease_seconds,
                stage="starting",
                started_at=now,
                versions=versions or {},
                error=None,
                error_code=None,
            )
            .returning(Job.id, Job.kind, Job.attempt, Job.tenant_id, Job.mesh_id, Job.poses_id, Job.params,
                       Job.parent_id, Job.phase, Job.window_index)
        )
        with self._write() as session, session.begin():
            row = session.execute(stmt, execution_options={"synchronize_session": False}).first()
        return Claimed(*row) if row else None

    def _fenced(self, job_id: str, attempt: int, **values: Any) -> bool:
        stmt = (update(Job).where(Job.id == job_id, Job.attempt == attempt, Job.state == "running")
                .values(**values).execution_options(synchronize_session=False))
        with self._write() as session, session.begin():
            return session.execute(stmt).rowcount == 1

    def heartbeat(self, job_id: str, attempt: int) -> bool:
        """Renew the lease of a running attempt; False if the attempt lost the job."""
        return self._fenced(job_id, attempt, lease_expires=time.time() + self.policy.lease_seconds)

    def report(self, job_id: str, attempt: int, fraction: float, stage: str) -> bool:
        """Write progress (0..1) and stage text of a running attempt, renewing its lease. Progress never goes
        down (a retried attempt starting again keeps the job's highest)."""
        value = float(min(max(fraction, 0.0), 1.0))
        return self._fenced(job_id, attempt, progress=case((Job.progress > value, Job.progress), else_=value),
                            stage=stage[:200],
                            lease_expires=time.time() + self.policy.lease_seconds)

    def finish(self, job_id: str, attempt: int, write: Callable[[Session], dict[str, Any]]) -> bool:
        """Fenced success: ``write(session)`` adds the result rows and returns the result ids; they are
        committed together with ``state = 'succeeded'`` only if this attempt still owns the job."""
        with self._write() as session, session.begin():
            result = write(session)
            session.flush()
            stmt = (update(Job).where(Job.id == job_id, Job.attempt == attempt, Job.state == "running")
                    .values(state="succeeded", progress=1.0, stage="done", result=result, lease_expires=None,
                            finished_at=time.time()).execution_options(synchronize_session=False))
            if session.execute(stmt).rowcount != 1:
                session.rollback()
                return False
        return True

    def store_partial(
        self, job_id: str, attempt: int, write: Callable[[Session], dict[str, Any]]
    ) -> dict | None:
        """Fenced partial result while the attempt runs: ``write(session)`` adds rows and returns their ids,
        merged into ``jobs.result``; committed only if this attempt still owns the job (else None)."""
        with self._write() as session, session.begin():
            job = session.execute(
                select(Job)
                .where(Job.id == job_id, Job.attempt == attempt, Job.state == "running")
                .with_for_update()
            ).scalar_one_or_none()
            if job is None:
                return None
            ids = write(session)
            job.result = {**(job.result or {}), **ids}
        return ids

    def fail(self, job_id: str, attempt: int, message: str, code: str, retry: bool,
             result: dict[str, Any] | None = None) -> str | None:
        """Fenced failure: back to queued with backoff while attempts remain (if ``retry``), else failed;
        ``result`` replaces the job's result (e.g. poses kept from a failed fit). Returns the new state, or
        None if this attempt no longer owns the job."""
        with self._write() as session, session.begin():
            return self._fail_locked(session, job_id, attempt, message, code, retry, expired_only=False,
                                     result=result)

    def release(self, job_id: str, attempt: int) -> bool:
        """Give a running job back to the queue without counting a failure (worker shutting down)."""
        return self._fenced(job_id, attempt, state="queued", lease_expires=None, worker_id=None,
                            run_after=time.time(), stage="queued (released by a stopping worker)")

    def cancel(self, job_ids: list[str]) -> int:
        """Cancel queued or running jobs at once: a queued one is never claimed; a running attempt's next
        fenced write (heartbeat or progress) fails, so its worker stops it. The window tasks of a cancelled
        fit are cancelled with it. Returns how many of ``job_ids`` changed."""
        if not job_ids:
            return 0
        tasks = (update(Job).where(Job.parent_id.in_(job_ids), Job.state.in_(ACTIVE))
                 .values(state="cancelled", stage="cancelled with its fit job", lease_expires=None,
                         finished_at=time.time())
                 .execution_options(synchronize_session=False))
        stmt = (update(Job).where(Job.id.in_(job_ids), Job.state.in_(ACTIVE))
                .values(state="cancelled", stage="cancelled", lease_expires=None, finished_at=time.time())
                .execution_options(synchronize_session=False))
        with self._write() as session, session.begin():
            changed = session.execute(stmt).rowcount  # fit jobs before their tasks: the order of every writer
            session.execute(tasks)
            return changed

    def reap(self, limit: int = 100) -> int:
        """Return running jobs whose lease expired to the queue (or fail them past max attempts)."""
        now = time.time()
        with self.engine.connect() as conn:
            rows = conn.execute(
                select(Job.id, Job.attempt)
                .where(Job.state == "running", Job.lease_expires < now)
                .limit(limit)
            ).all()
        done = 0
        for job_id, attempt in rows:
            with self._write() as session, session.begin():
                msg = f"attempt {attempt} lost its worker (lease expired)"
                done += self._fail_locked(session, job_id, attempt, msg, "lease_expired", True,
                                          expired_only=True) is not None
        return done

    def _fail_locked(self, session: Session, job_id: str, attempt: int, message: str, code: str,
                     retry: bool, expired_only: bool, result: dict[str, Any] | None = None) -> str | None:
        lock_parent_first(session, job_id)
        query = select(Job).where(Job.id == job_id, Job.attempt == attempt, Job.state == "running")
        if expired_only:
            query = query.where(Job.lease_expires < time.time())
        job = session.execute(query.with_for_update()).scalar_one_or_none()
        if job is None:
            return None
        job.failures += 1
        if result is not None:
            job.result = result
        job.error, job.error_code, job.lease_expires, job.worker_id = message[:4000], code, None, None
        if retry and job.failures < job.max_attempts:
            job.state, job.run_after = "queued", time.time() + self.policy.backoff(job.failures)
            job.stage = f"retry after failed attempt {attempt}"
        else:
            job.state, job.finished_at = "failed", time.time()
            job.stage = "failed"
            if retry:
                job.error = f"gave up after {job.failures} attempts; last: {message}"[:4000]
            if job.parent_id:
                fail_parent(session, job)
        return job.state
