"""Dependencies of the routes, declared once as ``Annotated`` aliases."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session

from ..settings import Settings
from ..store.context import Store
from ..store.tenants import hash_key, tenant_for_key
from .cache import ClipCache
from .errors import ApiError

bearer = HTTPBearer(auto_error=False, description="an API key made with `pdeanim keys create --tenant NAME`")


def get_store(request: Request) -> Store:
    """The app's Store (engine, queue, blobs)."""
    return request.app.state.store


def get_settings(request: Request) -> Settings:
    """The app's Settings."""
    return request.app.state.store.settings


def get_clip_cache(request: Request) -> ClipCache:
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
    """Recently verified API keys (by hash) -> tenant, for ``ttl`` seconds, so hot routes skip a query."""

    def __init__(self, ttl: float = 30.0, max_entries: int = 10_000):
        self.ttl, self.max_entries = ttl, max_entries
        self._items: dict[str, tuple[str, float]] = {}
        self._lock = threading.Lock()

    def lookup(self, key: str, store: Store) -> str | None:
        """The tenant owning ``key`` (cached if verified less than ``ttl`` seconds ago), or None."""
        digest, now = hash_key(key), time.monotonic()
        with self._lock:
            hit = self._items.get(digest)
        if hit is not None and hit[1] > now:
            return hit[0]
        with store.sessions() as session:
            tenant = tenant_for_key(session, key)
        if tenant is not None:
            with self._lock:
                if len(self._items) >= self.max_entries:
                    self._items.clear()
                self._items[digest] = (tenant, now + self.ttl)
        return tenant


def get_tenant(creds: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)], store: StoreDep,
               request: Request) -> str:
    """The tenant id of the request's ``Authorization: Bearer KEY``; 401 when missing or unknown."""
    challenge = {"WWW-Authenticate": "Bearer"}
    if creds is None or not creds.credentials:
        raise ApiError(401, "unauthorized", "missing API key: send Authorization: Bearer KEY", challenge)
    tenant = request.app.state.key_cache.lookup(creds.credentials, store)
    if tenant is None:
        raise ApiError(401, "unauthorized", "invalid API key", challenge)
    request.state.tenant = tenant  # for the access log line
    return tenant


TenantDep = Annotated[str, Depends(get_tenant)]
