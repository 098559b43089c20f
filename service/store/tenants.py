"""Tenants and API keys: keys are random tokens shown once; only their SHA-256 is stored."""

from __future__ import annotations

import hashlib
import secrets

from sqlalchemy import select
from sqlalchemy.orm import Session

from ..settings import Settings
from .context import Store
from .models import ApiKey, Tenant

KEY_PREFIX = "pda_"


def hash_key(key: str) -> str:
    """SHA-256 hex of an API key (keys are 256-bit random, so a fast hash is enough)."""
    return hashlib.sha256(key.encode()).hexdigest()


def create_key(session: Session, tenant_name: str) -> tuple[str, Tenant]:
    """Create the tenant if new and a key for it; returns (the key in clear, tenant). Caller commits."""
    tenant = session.execute(select(Tenant).where(Tenant.name == tenant_name)).scalar_one_or_none()
    if tenant is None:
        tenant = Tenant(name=tenant_name)
        session.add(tenant)
        session.flush()
    key = KEY_PREFIX + secrets.token_urlsafe(32)
    session.add(ApiKey(tenant_id=tenant.id, key_hash=hash_key(key), prefix=key[:10]))
    return key, tenant


def issue_key(settings: Settings, tenant_name: str) -> str:
    """Migrate the database, create a key for ``tenant_name`` (and the tenant if new), commit, return the key:
    what ``pdeanim keys create``, the demo and the tests use. One write transaction from the start (BEGIN
    IMMEDIATE on SQLite): a read that later writes would fail with "database is locked" when the running
    service committed in between."""
    store = Store.open(settings, run_migrations=True)
    try:
        with Session(store.engine.execution_options(immediate=True)) as session:
            key, _ = create_key(session, tenant_name)
            session.commit()
        return key
    finally:
        store.close()


def tenant_for_key(session: Session, key: str) -> str | None:
    """The tenant id owning an active ``key``, or None."""
    row = session.execute(select(ApiKey.tenant_id).where(ApiKey.key_hash == hash_key(key),
                                                        ApiKey.revoked_at.is_(None))).first()
    return row[0] if row else None
