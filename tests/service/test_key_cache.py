"""The API key cache on a real store: concurrent requests for a key not cached make one query together, an
entry in the second half of its TTL is re-verified in the background while it keeps answering, and a
re-verification that finds the key revoked drops it at once."""

from __future__ import annotations

import asyncio
import time

import pytest
from sqlalchemy import update

from pdeanim_service.api.deps import KeyCache
from pdeanim_service.settings import Settings
from pdeanim_service.store.context import Store
from pdeanim_service.store.models import ApiKey
from pdeanim_service.store.tenants import hash_key, issue_key


@pytest.fixture
def store_and_key(tmp_path):
    settings = Settings(data_dir=tmp_path)
    key = issue_key(settings, "alice")
    store = Store.open(settings)
    yield store, key
    store.close()


def _revoke(store: Store, key: str) -> None:
    with store.sessions() as session:
        session.execute(update(ApiKey).where(ApiKey.key_hash == hash_key(key)).values(revoked_at=time.time()))
        session.commit()


def test_concurrent_misses_share_one_query(store_and_key):
    store, key = store_and_key
    cache = KeyCache(ttl=60)

    async def run() -> list:
        return await asyncio.gather(*(cache.verify(key, store) for _ in range(32)),
                                    cache.verify("not-a-key", store))

    tenants = asyncio.run(run())
    assert len(set(tenants[:-1])) == 1 and tenants[0] is not None and tenants[-1] is None
    assert cache.queries == 2  # one for the key, one for the unknown one
    assert cache.cached(key) == tenants[0]


async def _until(condition, seconds: float = 30.0) -> None:  # noqa: ANN001
    """Wait on the event loop until ``condition()`` holds; fails past ``seconds``."""
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, "condition not reached"
        await asyncio.sleep(0.01)


def test_second_half_refreshes_in_the_background_and_revocation_drops_the_key(store_and_key):
    store, key = store_and_key
    ttl = 1.0
    cache = KeyCache(ttl=ttl)

    async def run() -> None:
        tenant = await cache.verify(key, store)
        verified = time.monotonic()
        assert cache.queries == 1
        assert await cache.verify(key, store) == tenant and cache.queries == 1  # first half: no query
        await _until(lambda: time.monotonic() - verified > ttl / 2 + 0.05)  # the entry's second half
        assert await cache.verify(key, store) == tenant  # answered from the cache at once...
        await _until(lambda: cache.queries == 2 and not cache._pending)  # ...while one query re-verifies it
        refreshed = time.monotonic()
        _revoke(store, key)
        await _until(lambda: time.monotonic() - refreshed > ttl / 2 + 0.05)  # the new entry's second half
        await cache.verify(key, store)  # may still answer from the entry; starts the re-verification
        await _until(lambda: cache.queries == 3 and not cache._pending)
        assert cache.cached(key) is None and await cache.verify(key, store) is None

    asyncio.run(run())


def test_ttl_zero_asks_every_time(store_and_key):
    store, key = store_and_key
    cache = KeyCache(ttl=0)

    async def run() -> None:
        for _ in range(3):
            assert await cache.verify(key, store) is not None
        _revoke(store, key)
        assert await cache.verify(key, store) is None

    asyncio.run(run())
    assert cache.queries == 4
