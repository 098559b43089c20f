"""Lifecycle: list a tenant's meshes, poses, clips and jobs (cursor pages, filters); delete a mesh (with its
poses, clips and jobs) or a clip, removing the blobs nothing references any more."""

from __future__ import annotations

import time
from typing import Literal

from fastapi import APIRouter, Query, Request
from sqlalchemy import select

from ...store.lifecycle import delete_clip, delete_mesh
from ...store.models import ClipRecord, Job, Mesh, PosesRecord
from ..access import responses
from ..deps import SessionDep, StoreDep, TenantDep
from ..errors import ApiError
from ..pages import (
    CURSOR_PATTERN,
    DEFAULT_LIMIT,
    MAX_LIMIT,
    ClipPage,
    DeletedOut,
    JobPage,
    MeshPage,
    PosesPage,
    page,
)
from .clips import clip_out
from .jobs import job_out
from .meshes import mesh_out
from .poses import poses_out

router = APIRouter()
LIMIT = Query(DEFAULT_LIMIT, ge=1, le=MAX_LIMIT, description="items per page")
CURSOR = Query(None, pattern=CURSOR_PATTERN, description="next_cursor of the previous page")
ID = {"max_length": 64, "description": "only rows of this id"}


@router.get("/v1/meshes", operation_id="listMeshes", response_model=MeshPage, tags=["meshes"],
            responses=responses(401, 422))
def list_meshes(tenant: TenantDep, session: SessionDep, limit: int = LIMIT,
                cursor: str | None = CURSOR) -> MeshPage:
    """The tenant's meshes, newest first."""
    items, nxt = page(session, select(Mesh).where(Mesh.tenant_id == tenant), Mesh, limit, cursor, mesh_out)
    return MeshPage(items=items, next_cursor=nxt)


@router.get("/v1/poses", operation_id="listPoses", response_model=PosesPage, tags=["poses"],
            responses=responses(401, 422))
def list_poses(tenant: TenantDep, session: SessionDep, limit: int = LIMIT, cursor: str | None = CURSOR,
               mesh_id: str | None = Query(None, **ID),
               source: Literal["upload", "simulate"] | None = Query(None, description="how they were made"),
               ) -> PosesPage:
    """The tenant's poses, newest first; filter by mesh and source."""
    query = select(PosesRecord).where(PosesRecord.tenant_id == tenant)
    if mesh_id is not None:
        query = query.where(PosesRecord.mesh_id == mesh_id)
    if source is not None:
        query = query.where(PosesRecord.source == source)
    items, nxt = page(session, query, PosesRecord, limit, cursor, poses_out)
    return PosesPage(items=items, next_cursor=nxt)


@router.get("/v1/clips", operation_id="listClips", response_model=ClipPage, tags=["clips"],
            responses=responses(401, 422))
def list_clips(tenant: TenantDep, session: SessionDep, limit: int = LIMIT, cursor: str | None = CURSOR,
               mesh_id: str | None = Query(None, **ID), poses_id: str | None = Query(None, **ID),
               kind: Literal["dynamic-pde", "cyclic-spine"] | None = Query(
                   None, description='the clip\'s model: "dynamic-pde" (fit jobs, gait cycles) or '
                   '"cyclic-spine" (cyclic jobs in spine mode)'),
               ) -> ClipPage:
    """The tenant's clips, newest first; filter by mesh, poses and kind."""
    query = select(ClipRecord).where(ClipRecord.tenant_id == tenant)
    filters = ((ClipRecord.mesh_id, mesh_id), (ClipRecord.poses_id, poses_id), (ClipRecord.kind, kind))
    for column, value in filters:
        if value is not None:
            query = query.where(column == value)
    items, nxt = page(session, query, ClipRecord, limit, cursor, lambda row: clip_out(row, {}))
    return ClipPage(items=items, next_cursor=nxt)


@router.get("/v1/jobs", operation_id="listJobs", response_model=JobPage, tags=["jobs"],
            responses=responses(401, 422))
def list_jobs(tenant: TenantDep, session: SessionDep, limit: int = LIMIT, cursor: str | None = CURSOR,
              state: Literal["queued", "running", "succeeded", "failed", "cancelled"] | None = Query(None),
              kind: Literal["simulate", "fit", "cyclic", "export"] | None = Query(None),
              mesh_id: str | None = Query(None, **ID)) -> JobPage:
    """The tenant's jobs, newest first; filter by state, kind and mesh. The window tasks of a fit in windows
    are not listed (their fit job is, with its progress counting windows)."""
    query = select(Job).where(Job.tenant_id == tenant, Job.parent_id.is_(None))
    if state is not None:
        states = ("running", "waiting") if state == "running" else (state,)  # waiting: shown as running
        query = query.where(Job.state.in_(states))
    for column, value in ((Job.kind, kind), (Job.mesh_id, mesh_id)):
        if value is not None:
            query = query.where(column == value)
    items, nxt = page(session, query, Job, limit, cursor, job_out)
    return JobPage(items=items, next_cursor=nxt)


@router.delete("/v1/meshes/{mesh_id}", operation_id="deleteMesh", response_model=DeletedOut, tags=["meshes"],
               responses=responses(401, 404, 422))
def remove_mesh(mesh_id: str, request: Request, tenant: TenantDep, store: StoreDep) -> DeletedOut:
    """Delete the mesh with its poses, clips and jobs (queued and running jobs are cancelled first: a running
    one stops at its worker's next heartbeat); blobs that nothing else references are removed. Answers once
    no API process serves its clips any more (PDEANIM_CLIP_INVALIDATION_SECONDS after the commit)."""
    done = delete_mesh(store, mesh_id, tenant)
    if done is None:
        raise ApiError(404, "not_found", f"mesh {mesh_id!r} not found")
    _settle(request, done.clip_ids)
    return DeletedOut(**done.summary())


@router.delete("/v1/clips/{clip_id}", operation_id="deleteClip", response_model=DeletedOut, tags=["clips"],
               responses=responses(401, 404, 422))
def remove_clip(clip_id: str, request: Request, tenant: TenantDep, store: StoreDep) -> DeletedOut:
    """Delete the clip; its blobs are removed unless another clip uses them. Answers once no API process
    serves it any more (PDEANIM_CLIP_INVALIDATION_SECONDS after the commit)."""
    done = delete_clip(store, clip_id, tenant)
    if done is None:
        raise ApiError(404, "not_found", f"clip {clip_id!r} not found")
    _settle(request, done.clip_ids)
    return DeletedOut(**done.summary())


def _settle(request: Request, clip_ids: list[str]) -> None:
    """Forget deleted clips here at once, then wait out the other API processes' check interval (see
    service/api/invalidation.py), so that no process serves them to a request sent after the answer."""
    watch = request.app.state.deletions
    if clip_ids:
        watch.forget(clip_ids)
        time.sleep(watch.bound)
