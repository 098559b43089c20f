"""Deleting a mesh (with its poses, clips and jobs) or a clip (with its export jobs), and then the blobs
nothing references any more (an export job's GLB goes with its clip or mesh, row and blob).

Blobs are content-addressed and shared between rows and tenants (the same file uploaded twice is one blob;
tets are shared by mesh hash), so a blob is removed only when no row of any tenant still names it. Rows go
first, in one transaction; blobs after the commit, each under its lock after a reference check
(:mod:`pdeanim_service.store.blobrefs`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from sqlalchemy import delete, or_, select
from sqlalchemy.orm import Session

from .blobrefs import TETS_PREFIX, release, write_session
from .context import Store
from .models import ClipRecord, Job, Mesh, PosesRecord
from .queue import ACTIVE
from .windows import release_blobs as release_intermediates


@dataclass
class Deleted:
    """What a deletion removed: row counts, cancelled jobs, removed blob keys and clip ids (to evict)."""

    meshes: int = 0
    poses: int = 0
    clips: int = 0
    jobs: int = 0
    cancelled_jobs: int = 0
    blobs_removed: int = 0
    clip_ids: list[str] = field(default_factory=list)
    keys: set[str] = field(default_factory=set)  # the blobs the deleted rows named

    def summary(self) -> dict[str, int]:
        """The counts, for the API answer."""
        return {"meshes": self.meshes, "poses": self.poses, "clips": self.clips, "jobs": self.jobs,
                "cancelled_jobs": self.cancelled_jobs, "blobs_removed": self.blobs_removed}


def _delete(session: Session, model: type, condition) -> int:  # noqa: ANN001 - a SQL expression
    stmt = delete(model).where(condition).execution_options(synchronize_session=False)
    return session.execute(stmt).rowcount


def _tet_keys(jobs: list[Job]) -> set[str]:
    keys = set()
    for job in jobs:
        key = (job.result or {}).get("tet_cache_key")
        if isinstance(key, str) and key:
            keys.add(TETS_PREFIX + key)
    return keys


def _export_keys(jobs: list[Job]) -> set[str]:
    """Blob keys of the GLBs that export jobs of ``jobs`` stored."""
    keys = set()
    for job in jobs:
        key = (job.result or {}).get("export_key")
        if isinstance(key, str) and key:
            keys.add(key)
    return keys


def _of_clip(clip_id: str):  # noqa: ANN202 - a SQL expression
    """The export jobs of clip ``clip_id`` (an export job's params name its clip)."""
    return (Job.kind == "export") & (Job.params["clip_id"].as_string() == clip_id)


def delete_mesh(store: Store, mesh_id: str, tenant_id: str) -> Deleted | None:
    """Delete a tenant's mesh with its poses, clips and jobs (running jobs cancelled first, so their workers
    stop at the next heartbeat), then the blobs left unreferenced. None if the mesh is not the tenant's."""
    out = delete_mesh_rows(store, mesh_id, tenant_id)
    if out is not None:
        out.blobs_removed = release(store, out.keys)
    return out


def delete_mesh_rows(store: Store, mesh_id: str, tenant_id: str) -> Deleted | None:
    """The rows of :func:`delete_mesh` (and a windowed fit's intermediates), in one transaction; the blobs
    they named are in ``keys``, for :func:`pdeanim_service.store.blobrefs.release`."""
    out = Deleted()
    with store.sessions() as session:
        mesh = session.get(Mesh, mesh_id)
        if mesh is None or mesh.tenant_id != tenant_id:
            return None
        active = session.scalars(select(Job.id).where(Job.mesh_id == mesh_id, Job.state.in_(ACTIVE),
                                                      Job.parent_id.is_(None))).all()
    out.cancelled_jobs = store.queue.cancel(list(active))  # with their window tasks
    with write_session(store) as session, session.begin():
        # locked first (PostgreSQL): a poses upload committing meanwhile is either seen here or sees none
        mesh = session.get(Mesh, mesh_id, with_for_update=True)
        if mesh is None:
            return None  # deleted meanwhile by a concurrent request
        poses_ids = select(PosesRecord.id).where(PosesRecord.mesh_id == mesh_id)
        clips = session.scalars(select(ClipRecord).where(ClipRecord.mesh_id == mesh_id)).all()
        poses = session.scalars(select(PosesRecord).where(PosesRecord.mesh_id == mesh_id)).all()
        of_mesh = or_(Job.mesh_id == mesh_id, Job.poses_id.in_(poses_ids))
        jobs = session.scalars(select(Job).where(of_mesh)).all()
        keys = {mesh.blob_key} | {p.blob_key for p in poses} | _tet_keys(jobs) | _export_keys(jobs)
        out.keys = keys | {c.topology_key for c in clips} | {c.coefficients_key for c in clips}
        out.clip_ids = [c.id for c in clips]
        out.clips = _delete(session, ClipRecord, ClipRecord.mesh_id == mesh_id)
        out.jobs = _delete(session, Job, of_mesh)
        out.poses = _delete(session, PosesRecord, PosesRecord.mesh_id == mesh_id)
        out.meshes = _delete(session, Mesh, Mesh.id == mesh_id)
        windowed = {j.id: int(j.result["windows"]) for j in jobs
                    if j.parent_id is None and isinstance((j.result or {}).get("windows"), int)}
    for job_id, n_windows in windowed.items():  # a windowed fit's intermediates (no row names them)
        release_intermediates(store.blobs, job_id, n_windows)
    return out


def delete_clip(store: Store, clip_id: str, tenant_id: str) -> Deleted | None:
    """Delete a tenant's clip with its export jobs (active ones cancelled first), then its blobs and their
    GLBs if nothing else uses them. None if not the tenant's."""
    out = Deleted(clip_ids=[clip_id])
    with store.sessions() as session:
        clip = session.get(ClipRecord, clip_id)
        if clip is None or clip.tenant_id != tenant_id:
            return None
        active = session.scalars(select(Job.id).where(_of_clip(clip_id), Job.state.in_(ACTIVE))).all()
    out.cancelled_jobs = store.queue.cancel(list(active))
    with write_session(store) as session, session.begin():
        clip = session.get(ClipRecord, clip_id)
        if clip is None or clip.tenant_id != tenant_id:
            return None  # deleted meanwhile by a concurrent request
        jobs = session.scalars(select(Job).where(_of_clip(clip_id))).all()
        keys = {clip.topology_key, clip.coefficients_key} | _export_keys(jobs)
        out.jobs = _delete(session, Job, _of_clip(clip_id))
        out.clips = _delete(session, ClipRecord, ClipRecord.id == clip_id)
    out.blobs_removed = release(store, keys)
    return out


def release_window_blobs(store: Store, job_ids: list[str]) -> None:
    """Remove the intermediates of the windowed fits among ``job_ids`` that ended (e.g. just cancelled)."""
    with store.sessions() as session:
        rows = session.execute(select(Job.id, Job.result).where(Job.id.in_(job_ids), Job.state.not_in(ACTIVE),
                                                                Job.parent_id.is_(None))).all()
    for job_id, result in rows:
        if isinstance((result or {}).get("windows"), int):
            release_intermediates(store.blobs, job_id, int(result["windows"]))
