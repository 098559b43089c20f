"""Service and worker settings from environment variables (prefix ``PDEANIM_``), with embedded defaults.

Embedded default: SQLite and a blob directory under ``./pdeanim-data``. Scale-out: set
``PDEANIM_DATABASE_URL=postgresql+psycopg://...`` and ``PDEANIM_BLOB_URL=s3://bucket/prefix`` (with
``PDEANIM_S3_ENDPOINT_URL`` for MinIO/moto; credentials come from the usual ``AWS_*`` variables).
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    """Every knob of the API and the worker; built explicitly (no global instance) so tests can choose."""

    model_config = SettingsConfigDict(env_prefix="PDEANIM_", extra="ignore")

    data_dir: Path = Field(Path("pdeanim-data"), description="root of the embedded database, blobs and temp files")
    database_url: str = Field("", description="SQLAlchemy URL; default sqlite:///DATA_DIR/pdeanim.sqlite3")
    blob_url: str = Field("", description="file:///path or s3://bucket/prefix; default file://DATA_DIR/blobs")
    s3_endpoint_url: str | None = Field(None, description="S3 endpoint for MinIO/moto; None = AWS")
    s3_region: str = "us-east-1"

    max_upload_bytes: int = Field(50 * 1024 * 1024, gt=0)
    max_vertices: int = Field(500_000, gt=0)
    max_faces: int = Field(1_000_000, gt=0)
    max_frames: int = Field(2_000, gt=0)
    max_clip_cache: int = Field(32, ge=1, description="parsed clips kept in each API process")
    frame_cache_bytes: int = Field(128 * 1024 * 1024, ge=0, description="encoded frame and animation GLBs "
                                   "kept per API process (LRU by (clip, t) and (clip, fps)); 0 = off")
    key_cache_seconds: float = Field(10.0, ge=0, description="a verified API key is trusted this long "
                                     "without a database query (a revoked key stops working within it); "
                                     "0 = always ask")

    lease_seconds: float = Field(30.0, gt=0, description="a job's lease; the running worker renews it")
    max_attempts: int = Field(3, ge=1, description="attempts before a job fails for good")
    backoff_seconds: float = Field(2.0, ge=0, description="first retry delay; doubles per failed attempt")
    backoff_max_seconds: float = Field(300.0, ge=0)
    poll_seconds: float = Field(0.5, gt=0, description="worker idle poll interval")
    shutdown_grace_seconds: float = Field(20.0, ge=0, description="on SIGTERM, time to finish the attempt")
    job_memory_bytes: int = Field(0, ge=0, description="RLIMIT_AS of a job's child process; 0 = unlimited")
    job_timeout_seconds: float = Field(3600.0, gt=0, description="an attempt running longer is killed")
    job_nice: int = Field(10, ge=0, le=19, description="nice increment of a job's process (the API keeps "
                          "its latency while jobs run); 0 = same priority")
    job_cpu_shares: int = Field(0, ge=0, description="cgroup v1 cpu.shares of the group `pdeanim-jobs` that "
                                "job processes join where /sys/fs/cgroup/cpu is writable; 0 = no cgroup")

    def resolved_data_dir(self) -> Path:
        """The data directory as an absolute path (created on demand)."""
        path = self.data_dir.expanduser().resolve()
        path.mkdir(parents=True, exist_ok=True)
        return path

    def resolved_database_url(self) -> str:
        """The database URL, defaulting to SQLite in the data directory."""
        return self.database_url or f"sqlite:///{self.resolved_data_dir() / 'pdeanim.sqlite3'}"

    def resolved_blob_url(self) -> str:
        """The blob store URL, defaulting to a directory in the data directory."""
        return self.blob_url or f"file://{self.resolved_data_dir() / 'blobs'}"

    def tmp_dir(self) -> Path:
        """Scratch space for uploads and job work directories (same file system as local blobs)."""
        path = self.resolved_data_dir() / "tmp"
        path.mkdir(parents=True, exist_ok=True)
        return path

    def cache_dir(self) -> Path:
        """Per-machine cache of expensive intermediate results (tetrahedral meshes)."""
        path = self.resolved_data_dir() / "cache"
        path.mkdir(parents=True, exist_ok=True)
        return path
