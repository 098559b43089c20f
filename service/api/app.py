"""The FastAPI application factory: settings in, app out (no import-time engine or global settings)."""

from __future__ import annotations

import logging
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from starlette.concurrency import run_in_threadpool

from ..settings import Settings
from ..store.context import Store
from ..store.scratch import clean_stale
from . import validator
from .cache import BodyCache, ClipCache
from .deps import KeyCache
from .errors import install_error_handlers
from .guard import RequestGuard
from .invalidation import DeletionWatch
from .memory import keep_freed_memory
from .middleware import install_http_middleware
from .routes import clips, health, jobs, lifecycle, meshes, poses
from .routes.pages import install_pages
from .threads import single_threaded_blas
from .uploadslots import UploadSlots
from .warmup import preload_recent_clips, warm_clip_routes

log = logging.getLogger("pdeanim.api")
API_VERSION = "1.0.0"
DESCRIPTION = (
    "Turn a deforming 3D mesh into a compact dynamic-PDE coefficient clip, and evaluate frames of it. "
    'Every 4xx/5xx answers `{"error": {"code", "message"}}`; every /v1 route needs '
    "`Authorization: Bearer KEY`."
)


def create_app(settings: Settings | None = None, store: Store | None = None) -> FastAPI:
    """Build the API on ``settings`` (default: from the environment); ``store`` may be injected by tests."""
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        keep_freed_memory()
        single_threaded_blas()  # frames are computed concurrently: BLAS threads would fight them
        if settings.warm_start:  # before the first request is accepted (uvicorn accepts after start-up)
            warm_clip_routes()
        own = app.state.store is None
        clean_stale(settings.tmp_dir())  # uploads cut short by a killed API process
        if own:
            app.state.store = Store.open(settings)
        threading.Thread(target=validator.warm, name="validator-warm", daemon=True).start()
        if settings.warm_start:
            await run_in_threadpool(preload_recent_clips, app.state.store, app.state.clip_cache,
                                    settings.preload_clips)
        stop_checks = app.state.deletions.start(app.state.store)
        yield
        stop_checks.set()
        log.info("deletion checks: %d; requests that found the last one stale and waited: %d",
                 app.state.deletions.checks, app.state.deletions.waits)
        if own:
            app.state.store.close()

    app = FastAPI(title="pdeanim", version=API_VERSION, description=DESCRIPTION, lifespan=lifespan,
                  docs_url=None, redoc_url=None)
    app.state.store = store
    app.state.clip_cache = ClipCache(settings.max_clip_cache, settings.clip_cache_bytes)
    app.state.frame_cache = BodyCache(settings.frame_cache_bytes)
    app.state.deletions = DeletionWatch(app.state.clip_cache, app.state.frame_cache,
                                        settings.clip_invalidation_seconds)
    app.state.key_cache = KeyCache(ttl=settings.key_cache_seconds)
    app.state.upload_slots = UploadSlots(settings.max_concurrent_uploads, settings.max_tenant_uploads)
    install_error_handlers(app)
    app.add_middleware(RequestGuard, max_header_bytes=settings.max_header_bytes,
                       max_json_bytes=settings.max_json_bytes, log_access=settings.access_log)
    for module in (health, meshes, poses, jobs, clips, lifecycle):
        app.include_router(module.router)
    install_pages(app)
    install_http_middleware(app, settings)
    return app


def app_from_environment() -> FastAPI:
    """Factory used by ``pdeanim serve`` (uvicorn ``factory=True``): settings from PDEANIM_* variables."""
    return create_app(Settings())
