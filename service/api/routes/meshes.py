"""Meshes: upload (validated by the library's mesh reader), stats, and the static topology part."""

from __future__ import annotations

from fastapi import APIRouter, Query, Request, Response
from starlette.concurrency import run_in_threadpool

from ...settings import Settings
from ...store.blobrefs import add_row
from ...store.models import ClipRecord, Mesh
from ..access import created, owned, responses
from ..deps import SessionDep, StoreDep, TenantDep
from ..errors import ApiError
from ..httpcache import immutable_response
from ..schemas import MeshOut
from ..uploads import UPLOAD_BODY, Upload, receive_file
from ..validator import run_checked

router = APIRouter(tags=["meshes"])


def mesh_out(row: Mesh) -> MeshOut:
    """Wire form of a mesh row."""
    stats = row.stats or {}
    return MeshOut(
        id=row.id,
        filename=row.filename,
        vertices=row.n_vertices,
        faces=row.n_faces,
        watertight=stats.get("watertight"),
        components=stats.get("components"),
        bbox=stats.get("bbox"),
        stats=stats,
        created_at=row.created_at,
    )


def _ingest(upload: Upload, settings: Settings) -> dict:
    """The mesh file's stats, read in a validator child (bounded API memory whatever the file)."""
    args = (str(upload.path), upload.filename, settings.model_dump_json())
    return run_checked("mesh_stats", args, settings)


@router.post("/v1/meshes", status_code=201, operation_id="uploadMesh", response_model=MeshOut,
             openapi_extra=UPLOAD_BODY, responses={**responses(400, 401, 408, 413, 415, 422, 429, 503),
                                                  **created(201, "mesh", {
                 "GetMesh": ("getMesh", "mesh_id"), "UploadPoses": ("uploadPoses", "mesh_id"),
                 "GetTopology": ("getMeshTopology", "mesh_id"), "DeleteMesh": ("deleteMesh", "mesh_id")})})
async def upload_mesh(request: Request, response: Response, tenant: TenantDep, store: StoreDep) -> MeshOut:
    """Upload a mesh file (OBJ, PLY, STL, OFF, GLB) as multipart field ``file``; 201 with its stats."""
    settings = store.settings
    with request.app.state.upload_slots.hold(tenant):
        upload = await receive_file(request, settings.tmp_dir(), settings.max_upload_bytes,
                                    settings.upload_pace())
        try:
            stats = await run_in_threadpool(_ingest, upload, settings)
            key = await run_in_threadpool(store.blobs.put_file, upload.path)
            row = Mesh(tenant_id=tenant, filename=upload.filename[:255], blob_key=key,
                       n_vertices=stats["vertices"], n_faces=stats["faces"], stats=stats)
            # the row and the check that its blob is stored, under the blob's lock (a database wait must not
            # stall the event loop); the upload is the source if a concurrent delete took the shared blob
            await run_in_threadpool(add_row, store, row, {key: upload.path})
        finally:
            upload.path.unlink(missing_ok=True)
    response.headers["Location"] = f"/v1/meshes/{row.id}"
    return mesh_out(row)


@router.get("/v1/meshes/{mesh_id}", operation_id="getMesh", response_model=MeshOut,
            responses=responses(401, 404, 422))
def get_mesh(mesh_id: str, tenant: TenantDep, session: SessionDep) -> MeshOut:
    """The mesh's stats: vertices, faces, components, watertight, bbox."""
    return mesh_out(owned(session, Mesh, mesh_id, tenant, "mesh"))


@router.get(
    "/v1/meshes/{mesh_id}/topology",
    operation_id="getMeshTopology",
    response_class=Response,
    responses={
        200: {
            "content": {"application/octet-stream": {}},
            "description": "the topology part (pdeanim container)",
        },
        **responses(304, 401, 404, 422),
    },
)
def get_topology(
    mesh_id: str,
    request: Request,
    tenant: TenantDep,
    session: SessionDep,
    store: StoreDep,
    clip_id: str | None = Query(
        None,
        description="required: the clip whose topology to send (a "
        "mesh may have clips of several kinds with different topologies)",
    ),
) -> Response:
    """The static part of clip ``clip_id`` of this mesh (prefer ``GET /v1/clips/{clip_id}/topology``)."""
    owned(session, Mesh, mesh_id, tenant, "mesh")
    if clip_id is None:
        raise ApiError(422, "clip_id_required",
                       "clip_id is required: a mesh may have several clips (fit, cyclic) whose topologies "
                       "differ, so ask for GET /v1/clips/CLIP_ID/topology or "
                       f"/v1/meshes/{mesh_id}/topology?clip_id=CLIP_ID")
    clip = owned(session, ClipRecord, clip_id, tenant, "clip")
    if clip.mesh_id != mesh_id:
        raise ApiError(404, "not_found", f"clip {clip_id!r} does not belong to mesh {mesh_id!r}")
    return immutable_response(request, clip.topology_key, lambda: store.blobs.get(clip.topology_key),
                              "application/octet-stream")


FILE_TYPES = {".glb": "model/gltf-binary", ".gltf": "model/gltf+json", ".obj": "model/obj",
              ".stl": "model/stl", ".ply": "application/octet-stream", ".off": "application/octet-stream"}


@router.get(
    "/v1/meshes/{mesh_id}/file",
    operation_id="getMeshFile",
    response_class=Response,
    responses={
        200: {"content": {t: {} for t in sorted(set(FILE_TYPES.values()))},
              "description": "the mesh file as uploaded (the media type of its extension)"},
        **responses(304, 401, 404, 422),
    },
)
def get_mesh_file(mesh_id: str, request: Request, tenant: TenantDep, session: SessionDep,
                  store: StoreDep) -> Response:
    """The file as uploaded (e.g. a GLB with its materials and textures: the viewer plays clips on it)."""
    row = owned(session, Mesh, mesh_id, tenant, "mesh")
    suffix = "." + row.filename.rsplit(".", 1)[-1].lower() if "." in row.filename else ""
    headers = {"Content-Disposition": f'attachment; filename="{mesh_id}{suffix}"'}
    return immutable_response(request, row.blob_key, lambda: store.blobs.get(row.blob_key),
                              FILE_TYPES.get(suffix, "application/octet-stream"), headers)
