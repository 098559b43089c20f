"""Deletes seen by every API process: each process keeps decoded clips and encoded bodies in its own caches,
and a DELETE reaches only the process that answered it. Every process therefore re-checks, at least every
``bound`` seconds, that the clips it holds (or is loading) still have their database rows, and serves a
cached clip only on a check that started at most ``bound`` seconds before the request was looked at; a
DELETE answers only ``bound`` seconds after its commit. A request sent after a DELETE's answer thus meets a
check that started after the commit and saw the row gone, in every process: 404, never the deleted clip.

The check is one indexed query for the ids held (none when nothing is cached), every ``bound / 4`` seconds
in the background; a request finds it stale only when the process fell behind (then it waits for a check of
its own). The coefficients, topology and export routes read their rows on every request and need none of
this."""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from typing import Any

from sqlalchemy import select
from starlette.concurrency import run_in_threadpool

from ..store.models import ClipRecord
from .cache import BodyCache, ClipCache
from .errors import ApiError

log = logging.getLogger("pdeanim.api")
QUERY_CHUNK = 500  # ids per IN (...) query


class DeletionWatch:
    """The deletion check of one API process over its clip cache and its encoded-body cache."""

    def __init__(self, clips: ClipCache, bodies: BodyCache, bound: float) -> None:
        self.clips, self.bodies, self.bound = clips, bodies, max(0.0, float(bound))
        self.checked_at = float("-inf")  # monotonic start of the newest check that completed
        self._lock = threading.Lock()
        self._pending: tuple[float, asyncio.Future] | None = None  # (start, future) of the check in flight
        self.checks = self.waits = 0  # checks made; requests that found the last one stale and waited

    def fresh(self, now: float | None = None) -> bool:
        """Whether a completed check started within ``bound`` seconds of ``now`` (no I/O)."""
        return (time.monotonic() if now is None else now) - self.checked_at < self.bound

    def check(self, store: Any) -> list[str]:
        """Query which held clips lost their rows and forget those (blocking); returns their ids."""
        started = time.monotonic()
        ids = self.clips.tracked()
        gone: list[str] = []
        if ids:
            existing: set[str] = set()
            with store.sessions() as session:
                for i in range(0, len(ids), QUERY_CHUNK):
                    chunk = ids[i:i + QUERY_CHUNK]
                    existing.update(session.scalars(select(ClipRecord.id).where(ClipRecord.id.in_(chunk))))
            gone = [i for i in ids if i not in existing]
        if gone:
            self.forget(gone)
            log.info("clips deleted by another process, dropped from this one's caches: %s", ", ".join(gone))
        with self._lock:
            self.checks += 1
            self.checked_at = max(self.checked_at, started)
        return gone

    def forget(self, clip_ids: list[str]) -> None:
        """Drop deleted clips from both caches (their decoded form and their frame/animation bodies)."""
        self.clips.forget(clip_ids)
        ids = set(clip_ids)
        self.bodies.drop_where(lambda key: isinstance(key, tuple) and any(
            isinstance(part, str) and part in ids for part in key))

    async def ensure(self, store: Any) -> None:
        """Return once a check that started at most ``bound`` seconds before now has completed: at once when
        the background one is recent, else after a check of its own (shared by the requests waiting)."""
        now = time.monotonic()
        if self.fresh(now):
            return
        self.waits += 1
        pending = self._pending
        if pending is None or pending[0] < now - self.bound:
            pending = self._start(store)
        await asyncio.shield(pending[1])

    def ensure_blocking(self, store: Any) -> None:
        """:meth:`ensure` for routes running in the thread pool (a check of their own when stale)."""
        if not self.fresh():
            self.waits += 1
            self.check(store)

    def _start(self, store: Any) -> tuple[float, asyncio.Future]:
        future = asyncio.ensure_future(run_in_threadpool(self.check, store))
        pending = (time.monotonic(), future)
        self._pending = pending

        def done(f: asyncio.Future) -> None:
            if self._pending is pending:
                self._pending = None
            if not f.cancelled() and f.exception() is not None:
                log.warning("clip deletion check failed: %r", f.exception())

        future.add_done_callback(done)
        return pending

    def start(self, store: Any) -> threading.Event:
        """Run the background check in a thread of its own, every ``bound / 4`` seconds (at least every
        10 ms), until the returned event is set. A thread, not a task: under CPU contention the event loop
        and the thread pool lag, and checks scheduled there went stale often enough that a third of the
        requests waited for one (load 15)."""
        stop = threading.Event()
        period = max(self.bound / 4, 0.01)

        def loop() -> None:
            while not stop.is_set():
                now = time.monotonic()
                try:
                    if self.clips.tracked():
                        self.check(store)
                    else:  # nothing held: nothing to re-check, and a later load reads the row after now
                        with self._lock:
                            self.checked_at = max(self.checked_at, now)
                except Exception as exc:  # noqa: BLE001 - the next round retries; requests then wait
                    log.warning("clip deletion check failed: %r", exc)
                    stop.wait(min(1.0, 10 * period))  # a database outage: do not log 16 lines a second
                stop.wait(period)

        threading.Thread(target=loop, name="pdeanim-deletion-check", daemon=True).start()
        return stop


def not_found(clip_id: str) -> ApiError:
    """The 404 of a missing (or deleted) clip."""
    return ApiError(404, "not_found", f"clip {clip_id!r} not found")
