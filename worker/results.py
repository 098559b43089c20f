"""Turn an attempt's outcome into result rows, written in the same transaction as the fenced success."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sqlalchemy.orm import Session

from service.store.models import ClipRecord, PosesRecord
from service.store.queue import Claimed


def result_writer(job: Claimed, result: dict[str, Any]) -> Callable[[Session], dict[str, Any]]:
    """A ``write(session)`` for :meth:`JobQueue.finish`: adds poses/clip rows, returns their ids."""

    def write(session: Session) -> dict[str, Any]:
        ids: dict[str, Any] = {}
        poses_id = job.poses_id
        if "poses" in result:
            p = result["poses"]
            row = PosesRecord(tenant_id=job.tenant_id, mesh_id=job.mesh_id, job_id=job.id, source="simulate",
                              blob_key=p["blob_key"], n_frames=p["n_frames"], n_vertices=p["n_vertices"],
                              meta=p.get("meta", {}))
            session.add(row)
            session.flush()
            poses_id = ids["poses_id"] = row.id
        if "clip" in result:
            c = result["clip"]
            row = ClipRecord(tenant_id=job.tenant_id, mesh_id=job.mesh_id, poses_id=poses_id, job_id=job.id,
                             kind=c["kind"], topology_key=c["topology_key"], coefficients_key=c["coefficients_key"],
                             topology_id=c["topology_id"], report=c.get("report", {}))
            session.add(row)
            session.flush()
            ids["clip_id"] = row.id
        return ids

    return write
