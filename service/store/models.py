"""SQLAlchemy 2 models of the metadata database (tenants, API keys, meshes, poses, clips, jobs).

Times that the queue compares (run_after, lease_expires) are float epoch seconds so both SQLite and
PostgreSQL compare them the same way; the others are float epoch seconds too for uniformity.
"""

from __future__ import annotations

import time
import uuid
from typing import Any

from sqlalchemy import JSON, Float, ForeignKey, Index, Integer, String, Text
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column


def new_id(prefix: str) -> str:
    """A random public id such as ``mesh_3f2a...`` (prefix says what it is)."""
    return f"{prefix}_{uuid.uuid4().hex}"


class Base(DeclarativeBase):
    """Declarative base of every table."""


class Tenant(Base):
    """A customer; every row below belongs to one."""

    __tablename__ = "tenants"
    id: Mapped[str] = mapped_column(String(40), primary_key=True, default=lambda: new_id("ten"))
    name: Mapped[str] = mapped_column(String(200), unique=True)
    created_at: Mapped[float] = mapped_column(Float, default=time.time)


class ApiKey(Base):
    """An API key of a tenant, stored as its SHA-256 only."""

    __tablename__ = "api_keys"
    id: Mapped[str] = mapped_column(String(40), primary_key=True, default=lambda: new_id("key"))
    tenant_id: Mapped[str] = mapped_column(ForeignKey("tenants.id"), index=True)
    key_hash: Mapped[str] = mapped_column(String(64), unique=True)
    prefix: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[float] = mapped_column(Float, default=time.time)
    revoked_at: Mapped[float | None] = mapped_column(Float, nullable=True)


class Mesh(Base):
    """An uploaded mesh: the original file as a blob, plus its stats."""

    __tablename__ = "meshes"
    id: Mapped[str] = mapped_column(String(40), primary_key=True, default=lambda: new_id("mesh"))
    tenant_id: Mapped[str] = mapped_column(ForeignKey("tenants.id"), index=True)
    filename: Mapped[str] = mapped_column(String(255))
    blob_key: Mapped[str] = mapped_column(String(200))
    n_vertices: Mapped[int] = mapped_column(Integer)
    n_faces: Mapped[int] = mapped_column(Integer)
    stats: Mapped[dict[str, Any]] = mapped_column(JSON)
    created_at: Mapped[float] = mapped_column(Float, default=time.time)

    __table_args__ = (
        Index("ix_meshes_list", "tenant_id", "created_at", "id"),
        Index("ix_meshes_blob_key", "blob_key"),
    )


class PosesRecord(Base):
    """Frames of a mesh (POSES.npz blob), uploaded or simulated by a job."""

    __tablename__ = "poses"
    id: Mapped[str] = mapped_column(String(40), primary_key=True, default=lambda: new_id("poses"))
    tenant_id: Mapped[str] = mapped_column(ForeignKey("tenants.id"), index=True)
    mesh_id: Mapped[str] = mapped_column(ForeignKey("meshes.id"), index=True)
    job_id: Mapped[str | None] = mapped_column(String(40), unique=True, nullable=True)  # producing job
    source: Mapped[str] = mapped_column(String(20))  # "upload" | "simulate"
    blob_key: Mapped[str] = mapped_column(String(200))
    n_frames: Mapped[int] = mapped_column(Integer)
    n_vertices: Mapped[int] = mapped_column(Integer)
    meta: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[float] = mapped_column(Float, default=time.time)

    __table_args__ = (
        Index("ix_poses_list", "tenant_id", "created_at", "id"),
        Index("ix_poses_blob_key", "blob_key"),
    )


class ClipRecord(Base):
    """A clip: topology and coefficients blobs plus the producer's report."""

    __tablename__ = "clips"
    id: Mapped[str] = mapped_column(String(40), primary_key=True, default=lambda: new_id("clip"))
    tenant_id: Mapped[str] = mapped_column(ForeignKey("tenants.id"), index=True)
    mesh_id: Mapped[str] = mapped_column(ForeignKey("meshes.id"), index=True)
    poses_id: Mapped[str | None] = mapped_column(ForeignKey("poses.id"), nullable=True)
    job_id: Mapped[str | None] = mapped_column(String(40), unique=True, nullable=True)  # producing job
    kind: Mapped[str] = mapped_column(String(40))
    topology_key: Mapped[str] = mapped_column(String(200))
    coefficients_key: Mapped[str] = mapped_column(String(200))
    topology_id: Mapped[str] = mapped_column(String(64))
    report: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[float] = mapped_column(Float, default=time.time)

    __table_args__ = (
        Index("ix_clips_list", "tenant_id", "created_at", "id"),
        Index("ix_clips_topology_key", "topology_key"),
        Index("ix_clips_coefficients_key", "coefficients_key"),
    )


class Job(Base):
    """A queued unit of work and its attempts (see pdeanim_service.store.queue)."""

    __tablename__ = "jobs"
    id: Mapped[str] = mapped_column(String(40), primary_key=True, default=lambda: new_id("job"))
    tenant_id: Mapped[str] = mapped_column(ForeignKey("tenants.id"), index=True)
    kind: Mapped[str] = mapped_column(String(20))
    state: Mapped[str] = mapped_column(
        String(20), default="queued"
    )  # queued|running|waiting|succeeded|failed|cancelled (waiting: a fit whose window tasks run)
    mesh_id: Mapped[str | None] = mapped_column(ForeignKey("meshes.id"), nullable=True)
    poses_id: Mapped[str | None] = mapped_column(ForeignKey("poses.id"), nullable=True)
    params: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)  # the whole validated request
    versions: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)  # library versions of the attempt
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    stage: Mapped[str] = mapped_column(String(200), default="queued")
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    error_code: Mapped[str | None] = mapped_column(String(60), nullable=True)
    result: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    attempt: Mapped[int] = mapped_column(Integer, default=0)  # fencing token: +1 on every claim
    failures: Mapped[int] = mapped_column(Integer, default=0)  # failed or lost attempts
    max_attempts: Mapped[int] = mapped_column(Integer, default=3)
    run_after: Mapped[float] = mapped_column(Float, default=time.time)
    lease_expires: Mapped[float | None] = mapped_column(Float, nullable=True)
    worker_id: Mapped[str | None] = mapped_column(String(200), nullable=True)
    created_at: Mapped[float] = mapped_column(Float, default=time.time)
    started_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    finished_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    # a window task of a fit in windows (pdeanim_service.store.windows): its fit job, window and phase
    parent_id: Mapped[str | None] = mapped_column(String(40), nullable=True)
    window_index: Mapped[int | None] = mapped_column(Integer, nullable=True)
    phase: Mapped[str | None] = mapped_column(String(20), nullable=True)  # gram|space|encode|join

    __table_args__ = (
        Index("ix_jobs_claim", "state", "run_after"),
        Index("ix_jobs_parent", "parent_id", "phase"),
        Index("ix_jobs_lease", "state", "lease_expires"),
        Index("ix_jobs_list", "tenant_id", "created_at", "id"),
        Index("ix_jobs_mesh_id", "mesh_id"),
    )
