"""Alembic environment: runs the migrations online against the configured URL."""

from __future__ import annotations

import os

from alembic import context

from pdeanim_service.store.db import make_engine
from pdeanim_service.store.models import Base

target_metadata = Base.metadata


def run_migrations_online() -> None:
    """Apply migrations on one connection (SQLite batch mode for ALTERs)."""
    cfg = context.config
    url = (context.get_x_argument(as_dictionary=True).get("url") or cfg.attributes.get("url")
           or os.environ.get("PDEANIM_DATABASE_URL") or cfg.get_main_option("sqlalchemy.url"))
    engine = make_engine(url)
    with engine.connect() as conn:
        context.configure(connection=conn, target_metadata=target_metadata,
                          render_as_batch=url.startswith("sqlite"))
        with context.begin_transaction():
            context.run_migrations()
    engine.dispose()


run_migrations_online()
