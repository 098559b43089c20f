"""Dependencies of the routes, declared once as ``Annotated`` aliases."""

from __future__ import annotations

import asyncio
import logging
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

log = logging.getLogger("pdeanim.api")
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
    a revoked key (``revoked_at`` set) therefore stops working at most ``ttl`` seconds later. In its second
    half an entry is re-verified in the background by one query while requests go on using it, and the
    requests that find no valid entry for a key wait on one query together instead of each making one (at
    every expiry, all the connections in flight would otherwise query at once)."""

    def __init__(self, ttl: float = 10.0, max_entries: int = 10_000):
        self.ttl, self.max_entries = ttl, max_entries
        self._items: dict[str, tuple[str, float]] = {}  # key hash -> (tenant, expiry on the monotonic clock)
        self._lock = threading.Lock()
        self._pending: dict[str, asyncio.Future] = {}  # key hash -> its query in flight (event loop only)
        self.queries = 0

    def cached(self, key: str) -> str | None:
        """The tenant of ``key`` if it was verified less than ``ttl`` seconds ago (no I/O)."""
        hit = self._items.get(hash_key(key))
        return hit[0] if hit is not None and hit[1] > time.monotonic() else None

    def query(self, key: str, store: Store) -> str | None:
        """Ask the database for the tenant owning ``key`` (blocking) and keep the answer for ``ttl`` seconds
        from the query's start; an unknown or revoked key is forgotten."""
        h = hash_key(key)
        expires = time.monotonic() + self.ttl
        with self._lock:
            self.queries += 1  # queries run on pool threads
        with store.sessions() as session:
            tenant = tenant_for_key(session, key)
        with self._lock:
            if tenant is None:
                self._items.pop(h, None)
            elif self.ttl > 0:
                if len(self._items) >= self.max_entries:
                    self._items.clear()
                self._items[h] = (tenant, expires)
        return tenant

    async def verify(self, key: str, store: Store) -> str | None:
        """The tenant owning ``key``, or None: from the cache (starting a background re-verification in the
        entry's second half), else from the query in flight for it, else from a new query."""
        if self.ttl <= 0:
            return await run_in_threadpool(self.query, key, store)
        h = hash_key(key)
        hit = self._items.get(h)
        now = time.monotonic()
        if hit is not None and hit[1] > now:
            if hit[1] - now < self.ttl / 2 and h not in self._pending:
                self._start(h, key, store)
            return hit[0]
        pending = self._pending.get(h) or self._start(h, key, store)
        return await asyncio.shield(pending)  # a request that goes away leaves the query to the others

    def _start(self, h: str, key: str, store: Store) -> asyncio.Future:
        future = asyncio.ensure_future(run_in_threadpool(self.query, key, store))
        self._pending[h] = future

        def done(f: asyncio.Future) -> None:
            self._pending.pop(h, None)
            if not f.cancelled() and f.exception() is not None:  # awaited requests get it; else logged
                log.warning("API key verification failed: %r", f.exception())

        future.add_done_callback(done)
        return future


async def get_tenant(creds: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
                     request: Request) -> str:
    """The tenant id of the request's ``Authorization: Bearer KEY``; 401 when missing or unknown. A key
    verified within the cache TTL costs no database query and no thread-pool hop."""
    challenge = {"WWW-Authenticate": "Bearer"}
    if creds is None or not creds.credentials:
        raise ApiError(401, "unauthorized", "missing API key: send Authorization: Bearer KEY", challenge)
    cache: KeyCache = request.app.state.key_cache
    tenant = await cache.verify(creds.credentials, request.app.state.store)
    if tenant is None:
        raise ApiError(401, "unauthorized", "invalid API key", challenge)
    request.state.tenant = tenant  # for the access log line
    return tenant


TenantDep = Annotated[str, Depends(get_tenant)]
