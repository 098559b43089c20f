"""Dependencies of the routes, declared once as ``Annotated`` aliases."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from ..settings import Settings
from ..store.context import Store
from ..store.tenants import hash_key, tenant_for_key
from .cache import ClipCache
from .errors import ApiError

bearer = HTTPBearer(auto_error=False, description="an API key made with `pdeanim keys create --tenant NAME`")


# The small dependencies are ``async def``: FastAPI runs a plain ``def`` dependency in the thread pool, a
# hop (and GIL hand-off) per dependency per request that cost more than the frame route's own work.
async def get_store(request: Request) -> Store:
    """The app's Store (engine, queue, blobs)."""
    return request.app.state.store


async def get_settings(request: Request) -> Settings:
    """The app's Settings."""
    return request.app.state.store.settings


async def get_clip_cache(request: Request) -> ClipCache:
    """The app's decoded-clip cache."""
    return request.app.state.clip_cache


StoreDep = Annotated[Store, Depends(get_store)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
ClipCacheDep = Annotated[ClipCache, Depends(get_clip_cache)]


def get_session(store: StoreDep) -> Iterator[Session]:
    """A database session for one request."""
    with store.sessions() as session:
        yield session


SessionDep = Annotated[Session, Depends(get_session)]


class KeyCache:
    """Recently verified API keys (by SHA-256) -> tenant for ``ttl`` seconds, so requests skip the database;
    a revoked key (``revoked_at`` set) therefore stops working at most ``ttl`` seconds later."""

    def __init__(self, ttl: float = 10.0, max_entries: int = 10_000):
        self.ttl, self.max_entries = ttl, max_entries
        self._items: dict[str, tuple[str, float]] = {}
        self._lock = threading.Lock()

    def cached(self, key: str) -> str | None:
        """The tenant of ``key`` if it was verified less than ``ttl`` seconds ago (no I/O)."""
        hit = self._items.get(hash_key(key))
        return hit[0] if hit is not None and hit[1] > time.monotonic() else None

    def lookup(self, key: str, store: Store) -> str | None:
        """The tenant owning ``key`` (cached, or asked from the database and cached), or None."""
        tenant = self.cached(key)
        if tenant is not None:
            return tenant
        expires = time.monotonic() + self.ttl
        with store.sessions() as session:
            tenant = tenant_for_key(session, key)
        if tenant is not None and self.ttl > 0:
            with self._lock:
                if len(self._items) >= self.max_entries:
                    self._items.clear()
                self._items[hash_key(key)] = (tenant, expires)
        return tenant


async def get_tenant(creds: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
                     request: Request) -> str:
    """The tenant id of the request's ``Authorization: Bearer KEY``; 401 when missing or unknown. A key
    verified within the cache TTL costs no database query and no thread-pool hop."""
    challenge = {"WWW-Authenticate": "Bearer"}
    if creds is None or not creds.credentials:
        raise ApiError(401, "unauthorized", "missing API key: send Authorization: Bearer KEY", challenge)
    cache: KeyCache = request.app.state.key_cache
    tenant = cache.cached(creds.credentials)
    if tenant is None:
        tenant = await run_in_threadpool(cache.lookup, creds.credentials, request.app.state.store)
    if tenant is None:
        raise ApiError(401, "unauthorized", "invalid API key", challenge)
    request.state.tenant = tenant  # for the access log line
    return tenant


TenantDep = Annotated[str, Depends(get_tenant)]
