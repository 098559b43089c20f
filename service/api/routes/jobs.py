"""Jobs: submit simulate / fit / cyclic / export work (parameters validated now), follow its state, and
download an export job's GLB."""

from __future__ import annotations

import asyncio
import time

from fastapi import APIRouter, Query, Request, Response
from sqlalchemy import select
from starlette.concurrency import run_in_threadpool

from ...jobspec import normalize_request
from ...settings import Settings
from ...store.context import Store
from ...store.lifecycle import release_window_blobs
from ...store.models import ClipRecord, Job, Mesh, PosesRecord
from ...store.queue import FINAL
from ..access import created, owned, responses
from ..deps import SessionDep, StoreDep, TenantDep
from ..errors import ApiError
from ..jobtypes import CyclicJob, ExportJob, FitJob, JobBody, SimulateJob, job_options
from ..schemas import ErrorBody, JobOut, JobResult

router = APIRouter(tags=["jobs"])


def job_out(job: Job) -> JobOut:
    """Wire form of a job row."""
    error = ErrorBody(code=job.error_code or "error", message=job.error) if job.error else None
    return JobOut(
        id=job.id,
        kind=job.kind,
        state="running" if job.state == "waiting" else job.state,  # a fit whose window tasks run
        progress=job.progress,
        stage=job.stage,
        error=error,
        attempt=job.attempt,
        mesh_id=job.mesh_id,
        poses_id=job.poses_id,
        result=JobResult(**(job.result or {})),
        params=job.params,
        versions=job.versions,
        created_at=job.created_at,
        started_at=job.started_at,
        finished_at=job.finished_at,
    )


def _inputs(req: SimulateJob | FitJob | CyclicJob | ExportJob, tenant: str,
            session) -> tuple[str, str | None]:  # noqa: ANN001
    if req.kind == "export":
        extra = req.model_extra or {}
        if any(extra.get(k) not in (None, False) for k in ("poses_id", "then_fit", "fit")):
            raise ApiError(422, "invalid_parameter", "an export job takes clip_id and export options only")
        clip = owned(session, ClipRecord, req.clip_id, tenant, "clip")
        if req.mesh_id and req.mesh_id != clip.mesh_id:
            raise ApiError(422, "invalid_parameter", f"clip {clip.id} belongs to mesh {clip.mesh_id}")
        return clip.mesh_id, None
    if (req.model_extra or {}).get("clip_id") is not None:
        raise ApiError(422, "invalid_parameter", f"a {req.kind} job takes no clip_id")
    if req.kind == "fit":
        if not req.poses_id and not req.mesh_id:
            raise ApiError(
                422, "invalid_parameter", "a fit job needs poses_id (or mesh_id to fit its latest poses)"
            )
        if not req.poses_id:
            poses = _latest_poses(session, owned(session, Mesh, req.mesh_id, tenant, "mesh"), tenant)
        else:
            poses = owned(session, PosesRecord, req.poses_id, tenant, "poses")
        if req.mesh_id and req.mesh_id != poses.mesh_id:
            raise ApiError(422, "invalid_parameter", f"poses {poses.id} belong to mesh {poses.mesh_id}")
        return poses.mesh_id, poses.id
    if (req.model_extra or {}).get("poses_id") is not None:
        raise ApiError(422, "invalid_parameter", f"a {req.kind} job takes no poses_id")
    return owned(session, Mesh, req.mesh_id, tenant, "mesh").id, None


def _check_fit_memory(session, spec: dict, mesh_id: str, poses_id: str | None,  # noqa: ANN001
                      settings: Settings) -> None:
    """413 now when the fit this job will run cannot fit the job memory limit (the worker checks it again):
    a fit that runs as window tasks is checked against its largest task's estimate."""
    from pdeanim.fit import FitOptions
    from pdeanim.fit.budget import check_fit_memory
    from pdeanim.fit.windowed import windowed_applies

    limit, tol = settings.job_memory_limit(), settings.fit_tolerances()
    if poses_id is not None:
        poses = session.get(PosesRecord, poses_id)
        tasks = settings.fit_window_tasks and windowed_applies(
            poses.n_frames, poses.n_vertices, FitOptions.from_dict(spec["params"]), tol)
        check_fit_memory(poses.n_frames, poses.n_vertices, limit, tol, tasks=tasks)
    elif spec.get("then_fit"):
        check_fit_memory(int(spec["params"]["frames"]), session.get(Mesh, mesh_id).n_vertices, limit, tol)


def _latest_poses(session, mesh: Mesh, tenant: str) -> PosesRecord:  # noqa: ANN001
    """The newest poses of ``mesh`` (uploaded or simulated) for a fit job that names only the mesh."""
    poses = session.scalars(
        select(PosesRecord)
        .where(PosesRecord.mesh_id == mesh.id, PosesRecord.tenant_id == tenant)
        .order_by(PosesRecord.created_at.desc(), PosesRecord.id.desc())
        .limit(1)
    ).first()
    if poses is None:
        raise ApiError(422, "invalid_parameter",
                       f"mesh {mesh.id} has no poses yet: upload poses or run a simulate job first")
    return poses


@router.post("/v1/jobs", status_code=202, operation_id="createJob", response_model=JobOut,
             responses={**responses(400, 401, 404, 413, 415, 422, 501), **created(202, "job", {
                 "GetJob": ("getJob", "job_id"), "CancelJob": ("cancelJob", "job_id")})})
def create_job(req: JobBody, tenant: TenantDep, session: SessionDep, store: StoreDep,
               response: Response) -> JobOut:
    """Queue a job; its parameters are validated now (422 with the reason) and kept with the job."""
    mesh_id, poses_id = _inputs(req, tenant, session)
    fit = req.fit.model_dump(exclude_unset=True) if getattr(req, "fit", None) is not None else None
    spec = normalize_request(req.kind, job_options(req), getattr(req, "then_fit", False), fit)
    if req.kind == "export":
        from ..exports import check_fps

        check_fps(spec["params"]["fps"], store.settings)
        spec["clip_id"] = req.clip_id
    frames = spec["params"].get("frames")
    if isinstance(frames, int) and frames > store.settings.max_frames:
        from pdeanim.errors import LimitError

        raise LimitError("frames", frames, store.settings.max_frames, "PDEANIM_MAX_FRAMES")
    _check_fit_memory(session, spec, mesh_id, poses_id, store.settings)
    # end the read transaction first: on SQLite (WAL) a read transaction that later writes fails at once with
    # "database is locked" when a worker committed in between; a transaction that starts by writing waits
    session.commit()
    job = store.queue.enqueue(session, tenant_id=tenant, kind=req.kind, params=spec, mesh_id=mesh_id,
                              poses_id=poses_id)
    session.commit()
    response.headers["Location"] = f"/v1/jobs/{job.id}"
    return job_out(job)


WAIT_INTERVAL = 0.25  # seconds between the server-side state checks of a long poll


def _load(store: Store, job_id: str, tenant: str) -> JobOut:
    with store.sessions() as session:  # a short session per check: no connection is held while waiting
        return job_out(owned(session, Job, job_id, tenant, "job"))


WAIT = Query(0.0, ge=0, le=3600, description="long poll: wait up to this many seconds (capped by "
             "PDEANIM_MAX_WAIT_SECONDS) for the job to change state or finish; 0 answers at once")


@router.get("/v1/jobs/{job_id}", operation_id="getJob", response_model=JobOut,
            responses=responses(401, 404, 422))
async def get_job(job_id: str, tenant: TenantDep, store: StoreDep, wait: float = WAIT) -> JobOut:
    """State (queued, running, succeeded, failed, cancelled), progress 0..1, stage, error and result ids;
    with ``wait``, answers as soon as the state changes (or at the end of the wait, unchanged)."""
    job = await run_in_threadpool(_load, store, job_id, tenant)
    deadline = time.monotonic() + min(wait, store.settings.max_wait_seconds)
    first = job.state
    while job.state == first and job.state not in FINAL and (left := deadline - time.monotonic()) > 0:
        await asyncio.sleep(min(WAIT_INTERVAL, left))
        job = await run_in_threadpool(_load, store, job_id, tenant)
    return job


@router.post("/v1/jobs/{job_id}/cancel", operation_id="cancelJob", response_model=JobOut,
             responses=responses(401, 404, 409, 422))
def cancel_job(job_id: str, tenant: TenantDep, store: StoreDep) -> JobOut:
    """Cancel a queued job at once, or a running one (its worker stops it at the next heartbeat); cancelling
    a cancelled job is a no-op; 409 for a job that already succeeded or failed."""
    job = _load(store, job_id, tenant)
    if job.state in ("succeeded", "failed"):
        raise ApiError(409, "conflict", f"job {job_id} already {job.state}")
    store.queue.cancel([job_id])
    release_window_blobs(store, [job_id])
    job = _load(store, job_id, tenant)
    if job.state in ("succeeded", "failed"):  # it finished between the check and the cancel
        raise ApiError(409, "conflict", f"job {job_id} already {job.state}")
    return job


@router.get("/v1/exports/{job_id}", operation_id="getExport", response_class=Response,
            responses={200: {"content": {"model/gltf-binary": {}}, "description": "the export job's GLB"},
                       **responses(304, 401, 404, 409, 422)})
def get_export(job_id: str, request: Request, tenant: TenantDep, session: SessionDep,
               store: StoreDep) -> Response:
    """The animation GLB an ``export`` job built (409 while the job has not succeeded); zstd- or gzip-encoded
    where Accept-Encoding allows, as the animation route."""
    from ..encoding import negotiated_response

    job = owned(session, Job, job_id, tenant, "job")
    if job.kind != "export":
        raise ApiError(404, "not_found", f"job {job_id!r} is a {job.kind} job, not an export")
    key = (job.result or {}).get("export_key")
    if job.state != "succeeded" or not key:
        raise ApiError(409, "not_ready",
                       f"export job {job_id} is {job.state}; download it when it has succeeded")
    return negotiated_response(request, key, lambda: store.blobs.get(key), "model/gltf-binary",
                               request.app.state.frame_cache, ("export", key))
