"""Service and worker settings from environment variables (prefix ``PDEANIM_``), with embedded defaults.

Embedded default: SQLite and a blob directory under ``./pdeanim-data``. Scale-out: set
``PDEANIM_DATABASE_URL=postgresql+psycopg://...`` and ``PDEANIM_BLOB_URL=s3://bucket/prefix`` (with
``PDEANIM_S3_ENDPOINT_URL`` for MinIO/moto; credentials come from the usual ``AWS_*`` variables).
"""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

MIN_JOB_MEMORY = 2 * 1024**3
"""The default limit never goes below this: the libraries a job imports reserve about 1 GiB of address
space."""


class Settings(BaseSettings):
    """Every knob of the API and the worker; built explicitly (no global instance) so tests can choose."""

    model_config = SettingsConfigDict(env_prefix="PDEANIM_", extra="ignore")

    data_dir: Path = Field(
        Path("pdeanim-data"), description="root of the embedded database, blobs and temp files"
    )
    database_url: str = Field("", description="SQLAlchemy URL; default sqlite:///DATA_DIR/pdeanim.sqlite3")
    blob_url: str = Field("", description="file:///path or s3://bucket/prefix; default file://DATA_DIR/blobs")
    s3_endpoint_url: str | None = Field(None, description="S3 endpoint for MinIO/moto; None = AWS")
    s3_region: str = "us-east-1"

    max_export_fps: float = Field(
        120.0, gt=0, description="highest fps of an animation export (GLB); above: 422"
    )
    max_sync_export_bytes: int = Field(
        32 * 1024 * 1024,
        ge=0,
        description="GET /v1/clips/{id}/animation builds an export in the request only "
        "while its sampled frames as raw float32 stay within this; larger ones need an export job",
    )

    max_upload_bytes: int = Field(50 * 1024 * 1024, gt=0)
    max_vertices: int = Field(500_000, gt=0)
    max_faces: int = Field(1_000_000, gt=0)
    max_frames: int = Field(2_000, gt=0)
    max_pose_bytes: int = Field(1024**3, gt=0, description="inflated size of an uploaded poses .npz's arrays")
    max_decoded_bytes: int = Field(1024**3, gt=0, description="what decoding one glTF upload may allocate "
                                   "in total (EXT_meshopt_compression views and decoded accessors); checked "
                                   "from the declared sizes before decoding")
    max_gltf_json_bytes: int = Field(32 * 1024**2, gt=0, description="size of a glTF upload's JSON")
    max_gltf_json_depth: int = Field(64, gt=0, description="nesting depth of a glTF upload's JSON")
    max_gltf_nodes: int = Field(20_000, gt=0, description="nodes a glTF upload may declare")
    max_gltf_primitives: int = Field(20_000, gt=0, description="mesh primitives a glTF upload's scene may "
                                     "place")
    max_gltf_accessors: int = Field(100_000, gt=0, description="accessors a glTF upload may declare")
    upload_memory_bytes: int = Field(2 * 1024**3, ge=0, description="address space the validation of one "
                                     "upload may add to its child process (RLIMIT_AS over the preloaded "
                                     "libraries); over it: 413; 0 = no limit")
    upload_timeout_seconds: float = Field(120.0, gt=0, description="longest validation of one upload")
    max_concurrent_uploads: int = Field(4, ge=1, description="uploads one API process receives and "
                                        "validates at once; more: 429 with Retry-After")
    max_tenant_uploads: int = Field(2, ge=1, description="uploads of one tenant one API process receives "
                                    "and validates at once; more: 429 with Retry-After")
    upload_min_bytes_per_second: float = Field(16384.0, ge=0, description="an upload body must arrive at "
                                               "least this fast on average after the grace; slower: 408 "
                                               "(0 = no minimum)")
    upload_body_grace_seconds: float = Field(10.0, ge=0, description="time an upload body gets before the "
                                             "minimum rate applies")
    http_worker_healthcheck_seconds: float = Field(
        120.0, gt=0, description="pdeanim serve with several HTTP processes: how long uvicorn's supervisor "
        "waits for a process to answer its health check before it kills and replaces it (uvicorn's own "
        "default, 5 s, kills processes that are still starting on a loaded host)")
    max_json_bytes: int = Field(1024**2, gt=0, description="largest non-upload request body (job requests)")
    max_header_bytes: int = Field(32 * 1024, gt=0, description="largest total size of a request's headers")
    access_log: bool = Field(True, description="one log line per request (logger pdeanim.access, level INFO)")
    max_clip_cache: int = Field(32, ge=1, description="parsed clips kept in each API process")
    clip_cache_bytes: int = Field(
        1024**3, ge=0, description="memory of the parsed clips kept in each API process (their evaluation "
        "tables grow with segments x vertices); the least recently used are dropped before a clip is "
        "kept, and a clip larger than this alone is never kept; 0 = no bound")
    warm_start: bool = Field(True, description="each API process imports the clip modules and loads the "
                             "compiled kernels (a few tiny bundled clips) before it accepts requests")
    preload_clips: int = Field(4, ge=0, description="with warm_start, each API process also decodes this "
                               "many of the newest clips before it accepts requests (their first frame "
                               "requests then wait for no load); 0 = none")
    clip_invalidation_seconds: float = Field(
        0.25, ge=0, le=5, description="a clip deleted through one API process is no longer served by any "
        "other within this: each re-checks the clips it holds this often (a query every quarter of it) and "
        "DELETE answers this long after its commit, so requests sent after the answer get 404 everywhere; "
        "0 = a query on every cached frame request")
    cors_origins: str = Field("", description="comma-separated origins allowed by CORS (``*`` for any); "
                              "empty = CORS off")
    frame_cache_bytes: int = Field(128 * 1024 * 1024, ge=0, description="encoded frame and animation GLBs "
                                   "kept per API process (LRU by (clip, t) and (clip, fps)); 0 = off")
    stream_window_seconds: float = Field(2.0, gt=0, le=3600, description="source seconds per window of the "
                                         "streamable layout served by ``GET .../coefficients?layout=stream`` "
                                         "(docs/format.md §3.10): shorter windows start playing sooner and "
                                         "cost a few KB more each")
    key_cache_seconds: float = Field(10.0, ge=0, description="a verified API key is trusted this long "
                                     "without a database query (a revoked key stops working within it; a "
                                     "key in use is re-verified in the background in the second half); "
                                     "0 = always ask")
    max_wait_seconds: float = Field(30.0, ge=0, description="longest GET /v1/jobs/{id}?wait= long poll")

    blob_sweep_seconds: float = Field(3600.0, ge=0, description="each worker removes the blobs that no row "
                                      "names this often (the first sweep this long after it starts); "
                                      "0 = never (run `pdeanim blobs sweep` instead)")
    blob_sweep_grace_seconds: float = Field(3600.0, ge=0, description="a blob that no row names is removed "
                                            "by the sweeper only once it was stored this long ago (an upload "
                                            "or a job between storing its blob and writing its row)")
    lease_seconds: float = Field(30.0, gt=0, description="a job's lease; the running worker renews it")
    max_attempts: int = Field(3, ge=1, description="attempts before a job fails for good")
    backoff_seconds: float = Field(2.0, ge=0, description="first retry delay; doubles per failed attempt")
    backoff_max_seconds: float = Field(300.0, ge=0)
    poll_seconds: float = Field(0.5, gt=0, description="worker idle poll interval")
    shutdown_grace_seconds: float = Field(20.0, ge=0, description="on SIGTERM, time to finish the attempt")
    job_memory_bytes: int = Field(0, ge=0, description="RLIMIT_AS of a job's child process; 0 = "
                                  "job_memory_fraction of the machine's memory")
    job_memory_fraction: float = Field(0.5, ge=0, le=1, description="default job memory limit as a fraction "
                                       "of the machine's physical memory (at least 2 GiB); 0 = unlimited")
    job_timeout_seconds: float = Field(3600.0, gt=0, description="an attempt running longer is killed")
    job_nice: int = Field(10, ge=0, le=19, description="nice increment of a job's process (the API keeps "
                          "its latency while jobs run); 0 = same priority")
    job_sched_idle: bool = Field(True, description="run job processes under Linux's SCHED_IDLE policy: "
                                 "they get the CPU time that the API and other processes leave (niced "
                                 "alone, a busy job still takes a share of a core from a busy API); "
                                 "false = nice only")
    job_cpu_shares: int = Field(0, ge=0, description="cgroup v1 cpu.shares of the group `pdeanim-jobs` that "
                                "job processes join where /sys/fs/cgroup/cpu is writable; 0 = no cgroup")
    fit_window_tasks: bool = Field(True, description="a fit job whose input is fitted in windows of frames "
                                   "runs as window tasks of the job queue (any worker takes a window); "
                                   "false = the whole windowed fit in one job process")
    fit_window_fit_values: int = Field(0, ge=0, description="frame-vertex values above which a fit runs in "
                                       "windows of frames; 0 = the library's (4,000,000)")
    fit_window_values: int = Field(0, ge=0, description="frame-vertex values per window of frames (the "
                                   "unit of a window task); 0 = the library's (4,194,304)")

    def upload_pace(self):  # noqa: ANN201 - pdeanim_service.api.uploadslots.BodyPace (imported when needed)
        """The slowest an upload body may arrive, from these settings."""
        from pdeanim_service.api.uploadslots import BodyPace

        return BodyPace(self.upload_min_bytes_per_second, self.upload_body_grace_seconds)

    def cors_origin_list(self) -> list[str]:
        """The allowed CORS origins (scheme://host[:port], no trailing slash); empty when CORS is off."""
        return [o.strip().rstrip("/") for o in self.cors_origins.split(",") if o.strip()]

    def job_memory_limit(self) -> int:
        """Bytes of address space a job's process may use (0: unlimited): job_memory_bytes when set, else
        job_memory_fraction of the physical memory, so one job cannot take the machine down."""
        if self.job_memory_bytes or not self.job_memory_fraction:
            return self.job_memory_bytes
        physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        return max(int(self.job_memory_fraction * physical), MIN_JOB_MEMORY)

    def fit_tolerances(self):  # noqa: ANN201 - pdeanim.fit.FitTolerances (imported lazily)
        """The fit tolerances of jobs: the library's, with the window sizes of these settings."""
        from pdeanim.fit.options import FitTolerances

        tol = FitTolerances()
        changes = {"window_fit_values": self.fit_window_fit_values, "window_values": self.fit_window_values}
        return replace(tol, **{k: v for k, v in changes.items() if v})

    def gltf_limits(self):  # noqa: ANN201 - pdeanim.gltf.document.GltfLimits (imported when needed)
        """The glTF declared-size limits of uploads, from these settings."""
        from pdeanim.gltf.document import GltfLimits

        return GltfLimits(max_json_bytes=self.max_gltf_json_bytes, max_json_depth=self.max_gltf_json_depth,
                          max_decoded_bytes=self.max_decoded_bytes, max_nodes=self.max_gltf_nodes,
                          max_primitives=self.max_gltf_primitives, max_accessors=self.max_gltf_accessors)

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
