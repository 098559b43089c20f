"""Turn an attempt's outcome into result rows, written in the same transaction as the fenced success."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from pdeanim_service.store.blobrefs import hold
from pdeanim_service.store.blobs import BlobStore
from pdeanim_service.store.models import ClipRecord, Job, PosesRecord
from pdeanim_service.store.queue import Claimed


def _upsert_poses(session: Session, job: Claimed, p: dict[str, Any]) -> str:
    """The job's simulated poses row (one per job: a partial store or an earlier attempt may have made it)."""
    row = session.execute(select(PosesRecord).where(PosesRecord.job_id == job.id)).scalar_one_or_none()
    if row is None:
        row = PosesRecord(tenant_id=job.tenant_id, mesh_id=job.mesh_id, job_id=job.id, source="simulate")
        session.add(row)
    row.blob_key, row.n_frames, row.n_vertices = p["blob_key"], p["n_frames"], p["n_vertices"]
    row.meta = p.get("meta", {})
    session.flush()
    return row.id


def result_blob_keys(result: dict[str, Any]) -> list[str]:
    """The blobs the rows of ``result`` will name: poses, the clip's parts, an export's GLB (tets are a cache
    that any simulation makes again, so they are not checked)."""
    keys = [result["poses"]["blob_key"]] if "poses" in result else []
    if "clip" in result:
        keys += [result["clip"]["topology_key"], result["clip"]["coefficients_key"]]
    if "export" in result:
        keys.append(result["export"]["blob_key"])
    return keys


def result_writer(job: Claimed, result: dict[str, Any],
                  blobs: BlobStore) -> Callable[[Session], dict[str, Any]]:
    """A ``write(session)`` for :meth:`JobQueue.finish` or ``store_partial``: adds poses/clip rows, returns
    their ids (and the tet cache key of a simulation). Their blobs are checked under their locks first
    (:func:`pdeanim_service.store.blobrefs.hold`: BlobGone if a concurrent delete took a shared one)."""

    def write(session: Session) -> dict[str, Any]:
        # the job's row first, then the blobs' locks: the order of every transaction taking both
        session.execute(select(Job.id).where(Job.id == job.id).with_for_update())
        hold(session, blobs, dict.fromkeys(result_blob_keys(result)))
        ids: dict[str, Any] = {}
        poses_id = job.poses_id
        if "tet_cache_key" in result:
            ids["tet_cache_key"] = str(result["tet_cache_key"])
        if "poses" in result:
            poses_id = ids["poses_id"] = _upsert_poses(session, job, result["poses"])
        if "clip" in result:
            c = result["clip"]
            row = ClipRecord(
                tenant_id=job.tenant_id,
                mesh_id=job.mesh_id,
                poses_id=poses_id,
                job_id=job.id,
                kind=c["kind"],
                topology_key=c["topology_key"],
                coefficients_key=c["coefficients_key"],
                topology_id=c["topology_id"],
                report=c.get("report", {}),
            )
            session.add(row)
            session.flush()
            ids["clip_id"] = row.id
        if "export" in result:
            e = result["export"]
            ids.update(export_key=str(e["blob_key"]), export_bytes=int(e["bytes"]),
                       export_url=f"/v1/exports/{job.id}",
                       export={k: v for k, v in e.items() if k != "blob_key"})
        return ids

    return write
