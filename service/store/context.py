"""One object bundling what the API and the worker open from the settings: engine, sessions, queue, blobs."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import Engine, text
from sqlalchemy.orm import Session, sessionmaker

from ..settings import Settings
from .blobs import BlobStore, open_blob_store
from .db import make_engine, make_sessionmaker, migrate
from .queue import JobQueue, QueuePolicy


@dataclass
class Store:
    """Database engine, session factory, job queue and blob store built from one Settings."""

    settings: Settings
    engine: Engine
    sessions: sessionmaker[Session]
    queue: JobQueue
    blobs: BlobStore

    @classmethod
    def open(cls, settings: Settings, run_migrations: bool = False) -> Store:
        """Connect (and optionally migrate) according to ``settings``."""
        url = settings.resolved_database_url()
        if run_migrations:
            migrate(url)
        engine = make_engine(url)
        policy = QueuePolicy(
            settings.lease_seconds,
            settings.max_attempts,
            settings.backoff_seconds,
            settings.backoff_max_seconds,
        )
        return cls(
            settings, engine, make_sessionmaker(engine), JobQueue(engine, policy), open_blob_store(settings)
        )

    def check(self) -> dict[str, str]:
        """Reachability of the database and the blob store, as {"database": "ok"|error, "blobs": ...}."""
        status = {}
        try:
            with self.engine.connect() as conn:
                conn.execute(text("SELECT 1 FROM jobs LIMIT 1"))
            status["database"] = "ok"
        except Exception as exc:  # noqa: BLE001 - reported, not raised
            status["database"] = f"error: {type(exc).__name__}: {str(exc)[:200]}"
        try:
            self.blobs.ping()
            status["blobs"] = "ok"
        except Exception as exc:  # noqa: BLE001
            status["blobs"] = f"error: {type(exc).__name__}: {str(exc)[:200]}"
        return status

    def save(self, row: object) -> None:
        """Insert ``row`` in its own short transaction (blocking: call it from a thread in async code)."""
        with self.sessions() as session:
            session.add(row)
            session.commit()

    def close(self) -> None:
        """Release pooled connections."""
        self.engine.dispose()
