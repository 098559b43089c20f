"""Jobs: submit simulate / fit / cyclic / export work (parameters validated now), follow its state, and
download an export job's GLB."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response
from sqlalchemy import select

from ...jobspec import StageUnavailable, normalize_request
from ...store.models import ClipRecord, Job, Mesh, PosesRecord
from ..access import owned, responses
from ..deps import SessionDep, StoreDep, TenantDep
from ..errors import ApiError
from ..schemas import ErrorBody, JobOut, JobRequest, JobResult

router = APIRouter(tags=["jobs"])


def job_out(job: Job) -> JobOut:
    """Wire form of a job row."""
    error = ErrorBody(code=job.error_code or "error", message=job.error) if job.error else None
    return JobOut(id=job.id, kind=job.kind, state=job.state, progress=job.progress, stage=job.stage, error=error,
                  attempt=job.attempt, mesh_id=job.mesh_id, poses_id=job.poses_id,
                  result=JobResult(**(job.result or {})), params=job.params, versions=job.versions,
                  created_at=job.created_at, started_at=job.started_at, finished_at=job.finished_at)


def _inputs(req: JobRequest, tenant: str, session) -> tuple[str, str | None]:  # noqa: ANN001
    if req.clip_id is not None and req.kind != "export":
        raise ApiError(422, "invalid_parameter", f"a {req.kind} job takes no clip_id")
    if req.kind == "export":
        if not req.clip_id:
            raise ApiError(422, "invalid_parameter", "an export job needs clip_id")
        if req.poses_id or req.then_fit or req.fit is not None:
            raise ApiError(422, "invalid_parameter", "an export job takes clip_id and export options only")
        clip = owned(session, ClipRecord, req.clip_id, tenant, "clip")
        if req.mesh_id and req.mesh_id != clip.mesh_id:
            raise ApiError(422, "invalid_parameter", f"clip {clip.id} belongs to mesh {clip.mesh_id}")
        return clip.mesh_id, None
    if req.kind == "fit":
        if not req.poses_id and not req.mesh_id:
            raise ApiError(422, "invalid_parameter", "a fit job needs poses_id (or mesh_id to fit its latest poses)")
        if not req.poses_id:
            poses = _latest_poses(session, owned(session, Mesh, req.mesh_id, tenant, "mesh"), tenant)
        else:
            poses = owned(session, PosesRecord, req.poses_id, tenant, "poses")
        if req.mesh_id and req.mesh_id != poses.mesh_id:
            raise ApiError(422, "invalid_parameter", f"poses {poses.id} belong to mesh {poses.mesh_id}")
        return poses.mesh_id, poses.id
    if not req.mesh_id:
        raise ApiError(422, "invalid_parameter", f"a {req.kind} job needs mesh_id")
    if req.poses_id:
        raise ApiError(422, "invalid_parameter", f"a {req.kind} job takes no poses_id")
    return owned(session, Mesh, req.mesh_id, tenant, "mesh").id, None


def _latest_poses(session, mesh: Mesh, tenant: str) -> PosesRecord:  # noqa: ANN001
    """The newest poses of ``mesh`` (uploaded or simulated) for a fit job that names only the mesh."""
    poses = session.scalars(select(PosesRecord).where(PosesRecord.mesh_id == mesh.id, PosesRecord.tenant_id == tenant)
                            .order_by(PosesRecord.created_at.desc(), PosesRecord.id.desc()).limit(1)).first()
    if poses is None:
        raise ApiError(422, "invalid_parameter",
                       f"mesh {mesh.id} has no poses yet: upload poses or run a simulate job first")
    return poses


def _merged_params(req: JobRequest) -> dict:
    """``params`` plus parameters given flat next to ``kind``; a key given both ways is a 422."""
    flat = dict(req.model_extra or {})
    both = sorted(set(flat) & set(req.params))
    if both:
        raise ApiError(422, "invalid_parameter", f"parameters given both flat and in params: {', '.join(both)}")
    return {**req.params, **flat}


@router.post("/v1/jobs", status_code=202, operation_id="createJob", response_model=JobOut,
             responses=responses(401, 404, 413, 422, 501))
def create_job(req: JobRequest, tenant: TenantDep, session: SessionDep, store: StoreDep) -> JobOut:
    """Queue a job; its parameters are validated now (422 with the reason) and kept with the job."""
    mesh_id, poses_id = _inputs(req, tenant, session)
    try:
        spec = normalize_request(req.kind, _merged_params(req), req.then_fit, req.fit)
    except StageUnavailable as exc:
        raise ApiError(501, "not_implemented", str(exc)) from exc
    if req.kind == "export":
        from ..exports import check_fps

        check_fps(spec["params"]["fps"], store.settings)
        spec["clip_id"] = req.clip_id
    frames = spec["params"].get("frames")
    if isinstance(frames, int) and frames > store.settings.max_frames:
        from pdeanim.errors import LimitError

        raise LimitError("frames", frames, store.settings.max_frames, "PDEANIM_MAX_FRAMES")
    # end the read transaction first: on SQLite (WAL) a read transaction that later writes fails at once with
    # "database is locked" when a worker committed in between; a transaction that starts by writing waits
    session.commit()
    job = store.queue.enqueue(session, tenant_id=tenant, kind=req.kind, params=spec, mesh_id=mesh_id,
                              poses_id=poses_id)
    session.commit()
    return job_out(job)


@router.get("/v1/jobs/{job_id}", operation_id="getJob", response_model=JobOut, responses=responses(401, 404, 422))
def get_job(job_id: str, tenant: TenantDep, session: SessionDep) -> JobOut:
    """State (queued, running, succeeded, failed), progress 0..1, stage, error and result ids."""
    return job_out(owned(session, Job, job_id, tenant, "job"))


@router.get("/v1/exports/{job_id}", operation_id="getExport", response_class=Response,
            responses={200: {"content": {"model/gltf-binary": {}}, "description": "the export job's GLB"},
                       **responses(304, 401, 404, 409, 422)})
def get_export(job_id: str, request: Request, tenant: TenantDep, session: SessionDep,
               store: StoreDep) -> Response:
    """The animation GLB an ``export`` job built (409 while the job has not succeeded)."""
    from ..httpcache import immutable_response

    job = owned(session, Job, job_id, tenant, "job")
    if job.kind != "export":
        raise ApiError(404, "not_found", f"job {job_id!r} is a {job.kind} job, not an export")
    key = (job.result or {}).get("export_key")
    if job.state != "succeeded" or not key:
        raise ApiError(409, "not_ready",
                       f"export job {job_id} is {job.state}; download it when it has succeeded")
    return immutable_response(request, key, lambda: store.blobs.get(key), "model/gltf-binary")
