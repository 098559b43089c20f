"""Poses: upload poses made elsewhere for a mesh (.npz or animated GLB) and download any poses as .npz."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from fastapi import APIRouter, Query, Request, Response
from sqlalchemy import select
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from ...settings import Settings
from ...store.blobrefs import add_row, release
from ...store.context import Store
from ...store.models import Mesh, PosesRecord
from ...store.scratch import prefix
from ..access import created, owned, responses
from ..deps import SessionDep, StoreDep, TenantDep
from ..errors import ApiError
from ..httpcache import immutable_response
from ..schemas import PosesOut
from ..uploads import UPLOAD_BODY, Upload, receive_file
from ..validator import run_checked

router = APIRouter(tags=["poses"])


def poses_out(row: PosesRecord) -> PosesOut:
    """Wire form of a poses row."""
    return PosesOut(id=row.id, mesh_id=row.mesh_id, source=row.source, frames=row.n_frames,
                    vertices=row.n_vertices, job_id=row.job_id, created_at=row.created_at,
                    animation=(row.meta or {}).get("animation"))


def _owned_mesh(store: Store, mesh_id: str, tenant: str) -> Mesh:
    with store.sessions() as session:
        return owned(session, Mesh, mesh_id, tenant, "mesh")


def _validated(upload: Upload, mesh: Mesh, store: Store, fps: float,
               animation: str | None) -> tuple[Path, int, dict]:
    """The canonical POSES.npz written by a validator child (the caller deletes it), its frame count and the
    row's meta (with the glTF animation used, if any)."""
    settings: Settings = store.settings
    about = {"id": mesh.id, "n_vertices": mesh.n_vertices, "blob_key": mesh.blob_key,
             "filename": mesh.filename}
    out, frames, meta = run_checked("poses_file", (str(upload.path), upload.filename, about,
                                                   settings.model_dump_json(), fps, animation,
                                                   prefix("upload")), settings)
    return Path(out), frames, meta


def _mesh_still_there(mesh_id: str, tenant: str) -> Callable[[Session], bool]:
    """A check, run in the transaction that adds the poses row, that their mesh still exists (on PostgreSQL
    with a key-share lock, so a delete of the mesh waits for the insert or the insert sees it gone)."""
    def check(session: Session) -> bool:
        stmt = (select(Mesh.id).where(Mesh.id == mesh_id, Mesh.tenant_id == tenant)
                .with_for_update(read=True, key_share=True))
        return session.execute(stmt).first() is not None

    return check


def commit_poses(store: Store, key: str, source: Path, tenant: str, mesh: Mesh, frames: int,
                 meta: dict) -> PosesRecord | None:
    """Add the row of poses stored under ``key`` (``source``: their file, to restore the blob from if a
    concurrent delete took it), in one transaction with the blob's lock; None if their mesh was deleted
    meanwhile, and then no blob is left behind that no row names."""
    row = PosesRecord(tenant_id=tenant, mesh_id=mesh.id, source="upload", blob_key=key, n_frames=frames,
                      n_vertices=mesh.n_vertices, meta=meta)
    if add_row(store, row, {key: source}, _mesh_still_there(mesh.id, tenant)):
        return row
    release(store, [key])
    return None


def _store_poses(upload: Upload, mesh: Mesh, store: Store, tenant: str, fps: float,
                 animation: str | None) -> PosesRecord:
    """Validate, store the blob and add the row; 404 if the mesh was deleted meanwhile."""
    out, frames, meta = _validated(upload, mesh, store, fps, animation)
    try:
        row = commit_poses(store, store.blobs.put_file(out), out, tenant, mesh, frames, meta)
    finally:
        out.unlink(missing_ok=True)
    if row is None:
        raise ApiError(404, "not_found", f"mesh {mesh.id!r} not found (it was deleted while the poses were "
                                         "uploaded)")
    return row


@router.post("/v1/meshes/{mesh_id}/poses", status_code=201, operation_id="uploadPoses",
             response_model=PosesOut, openapi_extra=UPLOAD_BODY,
             responses={**responses(400, 401, 404, 408, 413, 415, 422, 429, 503),
                        **created(201, "poses", {"GetPoses": ("getPoses", "poses_id")})})
async def upload_poses(mesh_id: str, request: Request, response: Response, tenant: TenantDep,
                       store: StoreDep,
                       fps: float = Query(30.0, gt=0, le=1000, description="sampling rate for animated GLB"),
                       animation: str | None = Query(None, min_length=1, max_length=200, description=(
                           "glTF: the animation to sample, by name or index (default: the first); the "
                           "answer's animation field says which was used"))) -> PosesOut:
    """Upload poses of this mesh: a .npz with ``vertices`` (F,V,3) (optional ``faces``, ``times``) or an
    animated GLB (morph targets or several meshes); V must equal the mesh's vertex count."""
    mesh = await run_in_threadpool(_owned_mesh, store, mesh_id, tenant)
    settings = store.settings
    with request.app.state.upload_slots.hold(tenant):
        upload = await receive_file(request, settings.tmp_dir(), settings.max_upload_bytes,
                                    settings.upload_pace())
        try:
            row = await run_in_threadpool(_store_poses, upload, mesh, store, tenant, fps, animation)
        finally:
            upload.path.unlink(missing_ok=True)
    response.headers["Location"] = f"/v1/poses/{row.id}"
    return poses_out(row)


@router.get(
    "/v1/poses/{poses_id}",
    operation_id="getPoses",
    response_class=Response,
    responses={
        200: {
            "content": {
                "application/octet-stream": {},
                "application/json": {"schema": PosesOut.model_json_schema()},
            },
            "description": "POSES.npz (vertices, faces, times); metadata with Accept: application/json",
        },
        **responses(304, 401, 404, 422),
    },
)
def get_poses(
    poses_id: str, request: Request, tenant: TenantDep, session: SessionDep, store: StoreDep
) -> Response:
    """The poses as a .npz (``vertices`` (F,V,3) float32, ``faces``, ``times``), or metadata as JSON."""
    row = owned(session, PosesRecord, poses_id, tenant, "poses")
    if "application/json" in request.headers.get("accept", ""):
        return Response(poses_out(row).model_dump_json(), media_type="application/json")
    headers = {"Content-Disposition": f'attachment; filename="{poses_id}.npz"', "Vary": "Accept"}
    return immutable_response(request, row.blob_key, lambda: store.blobs.get(row.blob_key),
                              "application/octet-stream", headers, compress=False)  # float32 frames
