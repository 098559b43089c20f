"""Wire schemas (pydantic v2) of the API, kept apart from the storage models."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field


class ErrorBody(BaseModel):
    """The inside of every error answer."""

    code: str = Field(description="stable machine-readable code, e.g. invalid_mesh, not_found")
    message: str = Field(description="what went wrong, for people")


class ErrorOut(BaseModel):
    """Every 4xx/5xx answer."""

    error: ErrorBody


class Health(BaseModel):
    """Reachability of what the service depends on."""

    status: Literal["ok", "degraded"]
    database: str
    blobs: str


class MeshOut(BaseModel):
    """An uploaded mesh and its stats."""

    id: str
    filename: str
    vertices: int
    faces: int
    watertight: bool | None = Field(None, description="every edge shared by exactly two faces")
    components: int | None = Field(None, description="connected components")
    bbox: dict[str, list[float]] | None = Field(None, description='{"min": [x, y, z], "max": [x, y, z]}')
    stats: dict[str, Any] = Field(description="vertices, faces, components, watertight, bbox, diagonal")
    created_at: float


class PosesOut(BaseModel):
    """Poses of a mesh (download the frames from GET /v1/poses/{id})."""

    id: str
    mesh_id: str
    source: Literal["upload", "simulate"]
    frames: int
    vertices: int
    job_id: str | None = None
    animation: dict[str, Any] | None = Field(None, description='glTF uploads: the animation sampled, '
                                             '{"index": 0, "name": "Walk"}')
    created_at: float


class JobResult(BaseModel):
    """Ids of what a job made (a failed simulate + fit keeps its poses and names the failed stage)."""

    poses_id: str | None = None
    clip_id: str | None = None
    tet_cache_key: str | None = Field(None, description="tets a simulation used (blob tets-<key>, shared)")
    failed_stage: str | None = Field(
        None, description='the stage that failed after partial results, e.g. "fit"'
    )
    export_url: str | None = Field(
        None, description="export: where to download the GLB (GET /v1/exports/{job_id})"
    )
    export_bytes: int | None = Field(None, description="export: size of the GLB in bytes")
    windows: int | None = Field(None, description="fit: windows of frames the fit runs in as window tasks "
                                "(any worker takes one); progress counts them")
    windows_done: int | None = Field(None, description="fit: windows encoded so far")


class JobOut(BaseModel):
    """A job: state, progress, stage, error and result ids."""

    id: str
    kind: str
    state: Literal["queued", "running", "succeeded", "failed", "cancelled"]
    progress: float = Field(description="0..1")
    stage: str = Field(description='e.g. "simulate 40/100"')
    error: ErrorBody | None = None
    attempt: int
    mesh_id: str | None
    poses_id: str | None
    result: JobResult
    params: dict[str, Any] = Field(description="the validated request as the worker runs it")
    versions: dict[str, Any] = Field(description="library versions of the latest attempt")
    created_at: float
    started_at: float | None
    finished_at: float | None


class ClipOut(BaseModel):
    """Clip metadata: counts, sizes in bytes and the errors achieved."""

    id: str
    kind: str
    mesh_id: str
    poses_id: str | None
    job_id: str | None
    topology_id: str = Field(description="SHA-256 of the topology part (GET /v1/meshes/{id}/topology)")
    frames: int | None = None
    segments: int | None = None
    curves: int | None = None
    looping: bool | None = None
    sizes: dict[str, Any] = Field(default_factory=dict)
    errors: dict[str, Any] = Field(default_factory=dict, description="rms, max, rel_rms, ... achieved")
    info: dict[str, Any] = Field(default_factory=dict, description="the clip's own metadata")
    created_at: float
