"""Blob lifetime. Blobs are content-addressed and shared between rows and tenants (the same file uploaded
twice is one blob), so a blob may go only when no row names it, and a row may name a blob only while it is
stored. Both checks run under one lock per key:

- a writer stores the bytes, then, in the transaction that inserts its row, takes the key's lock and checks
  that the blob is still there, restoring it from its source file if a remover took it meanwhile
  (:func:`hold`, :func:`add_row`);
- a remover (a DELETE's :func:`release`, the :func:`sweep`er) takes the key's lock, checks that no row of any
  tenant names the key, and removes the blob before the lock is released.

A row committed under the lock names a stored blob, and every later remover sees that row, so no acknowledged
upload or job result loses its blob, whatever the interleaving. The lock is SQLite's write lock
(transactions begun with ``BEGIN IMMEDIATE``) or a PostgreSQL transaction-level advisory lock per key.
Blobs that no row names (an upload refused after its bytes were stored, a killed process) are removed by
:func:`sweep` once they are older than a grace period.
"""

from __future__ import annotations

import hashlib
import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy import select, text
from sqlalchemy.orm import Session

from .blobs import BlobStore
from .context import Store
from .models import ClipRecord, Job, Mesh, PosesRecord

log = logging.getLogger("pdeanim.api")
TETS_PREFIX = "tets-"  # blob key prefix of shared tets (pdeanim_worker.tetcache.BLOB_PREFIX)
# a windowed fit's own blobs (pdeanim_service.store.windows.blob_prefix), no row
INTERMEDIATES_PREFIX = "windowed/"
SWEEP_BATCH = 500
TEMP_FILE_SECONDS = 600.0  # a temporary file of a write is removed only this long after, whatever the grace


class BlobGone(RuntimeError):
    """A blob that a row was about to name is not stored, and there is no source to restore it from."""


def write_session(store: Store) -> Session:
    """A session whose transactions start by taking the write lock on SQLite (``BEGIN IMMEDIATE``: waits for
    the lock instead of failing), as every transaction that takes blob locks must."""
    return Session(store.engine.execution_options(immediate=True), expire_on_commit=False)


def _lock_id(key: str) -> int:
    """A signed 64-bit id of ``key`` for PostgreSQL's advisory locks (a collision only serialises more)."""
    return int.from_bytes(hashlib.blake2b(key.encode(), digest_size=8).digest(), "big", signed=True)


def lock_keys(session: Session, keys: Iterable[str]) -> None:
    """Take the locks of ``keys`` for the rest of the session's transaction (in one order, so two
    transactions taking several never deadlock)."""
    conn = session.connection()
    if conn.dialect.name == "sqlite":
        if not conn.get_execution_options().get("immediate"):
            raise RuntimeError("blob locks need a transaction begun with BEGIN IMMEDIATE (write_session)")
        return  # the transaction holds the database's write lock already
    for lock_id in sorted({_lock_id(k) for k in keys}):
        session.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": lock_id})


def hold(session: Session, blobs: BlobStore, keys: dict[str, Path | None]) -> None:
    """Under the keys' locks, make sure every blob of ``keys`` is stored, restoring it from its source file
    (the value) if a remover took it since it was written; BlobGone if it is missing and has no source. The
    row this transaction then adds names stored blobs, and stays protected once committed."""
    lock_keys(session, keys)
    for key, source in sorted(keys.items()):
        if blobs.exists(key):
            continue
        if source is None:
            raise BlobGone(f"blob {key} was removed before the row naming it was written")
        log.info("blob %s was removed by a concurrent delete before its row was written; stored again", key)
        blobs.put_file(source, key)


def add_row(store: Store, row: object, keys: dict[str, Path | None],
            check: Callable[[Session], bool] | None = None) -> bool:
    """Insert ``row``, which names the blobs of ``keys``, in one transaction with :func:`hold`; when
    ``check(session)`` (run under the locks) is false nothing is written and the answer is False."""
    with write_session(store) as session, session.begin():
        hold(session, store.blobs, keys)
        if check is not None and not check(session):
            session.rollback()
            return False
        session.add(row)
    return True


def referenced(session: Session, key: str) -> bool:
    """Whether any row of any tenant names blob ``key``."""
    return bool(named(session, [key]))


def named(session: Session, keys: list[str]) -> set[str]:
    """The keys among ``keys`` that some row of any tenant names (one query per kind of reference)."""
    if not keys:
        return set()
    tets = {k.removeprefix(TETS_PREFIX): k for k in keys if k.startswith(TETS_PREFIX)}
    found: set[str] = set()
    for column in (Mesh.blob_key, PosesRecord.blob_key, ClipRecord.topology_key, ClipRecord.coefficients_key):
        found |= set(session.scalars(select(column).where(column.in_(keys)).distinct()))
    export = Job.result["export_key"].as_string()
    found |= set(session.scalars(select(export).where(Job.kind == "export", export.in_(keys)).distinct()))
    if tets:
        tet = Job.result["tet_cache_key"].as_string()
        found |= {tets[k] for k in session.scalars(select(tet).where(tet.in_(list(tets))).distinct())}
    return found


def _release_one(store: Store, key: str) -> bool:
    """Remove blob ``key`` under its lock if no row names it; True if removed."""
    with write_session(store) as session, session.begin():
        lock_keys(session, [key])
        if referenced(session, key):
            return False
        store.blobs.delete(key)  # before the lock goes: a writer waiting for it then finds the blob missing
        return True


def release(store: Store, keys: Iterable[str]) -> int:
    """Remove each blob of ``keys`` that no row names any more (after a delete); how many were removed."""
    removed = 0
    for key in sorted(set(keys)):
        try:
            removed += _release_one(store, key)
        except Exception:  # noqa: BLE001 - an orphan blob wastes space but breaks nothing; the sweeper retries
            log.warning("could not remove unreferenced blob %s", key, exc_info=True)
    return removed


@dataclass
class Swept:
    """What one sweep did: blobs looked at (older than the grace), blobs removed, temp files removed."""

    checked: int = 0
    removed: int = 0
    temp_files: int = 0

    def summary(self) -> dict[str, int]:
        """The counts, for logs and the CLI."""
        return {"checked": self.checked, "removed": self.removed, "temp_files": self.temp_files}


def sweep(store: Store, grace_seconds: float, now: float | None = None) -> Swept:
    """Remove every blob that no row names and that was stored more than ``grace_seconds`` ago (the grace
    covers a writer between storing its blob and committing its row; :func:`hold` restores the blob for one
    that is slower), and stale temporary files. A windowed fit's intermediates are its job's to remove."""
    now = time.time() if now is None else now
    before = now - grace_seconds
    out = Swept(temp_files=store.blobs.remove_temp_files(min(before, now - TEMP_FILE_SECONDS)))
    batch: list[str] = []

    def flush() -> None:
        with store.sessions() as session:
            unnamed = sorted(set(batch) - named(session, batch))
        out.checked += len(batch)
        out.removed += release(store, unnamed)
        batch.clear()

    for key in store.blobs.keys(before):
        if key.startswith(INTERMEDIATES_PREFIX):
            continue
        batch.append(key)
        if len(batch) >= SWEEP_BATCH:
            flush()
    flush()
    if out.removed or out.temp_files:
        log.info("blob sweep: %s", out.summary())
    return out
