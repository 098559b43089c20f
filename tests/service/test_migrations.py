"""The migrations and the models agree: a fresh database migrated to the Alembic head has exactly the tables,
columns, types, indexes and constraints of the SQLAlchemy models, so a model change without a migration fails
here (and ``alembic revision --autogenerate`` would write the missing one)."""

from __future__ import annotations

import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import Column, Integer, MetaData, Table

from pdeanim_service.store.db import make_engine, migrate
from pdeanim_service.store.models import Base


def drift(url: str, metadata: MetaData) -> list:
    """What autogenerate would change to bring the migrated database to ``metadata``."""
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            context = MigrationContext.configure(conn, opts={"compare_type": True,
                                                             "compare_server_default": True})
            return compare_metadata(context, metadata)
    finally:
        engine.dispose()


@pytest.fixture
def migrated_url(backend) -> str:
    url = backend.settings().resolved_database_url()
    backend.settings().resolved_data_dir().mkdir(parents=True, exist_ok=True)
    migrate(url)
    return url


def test_head_matches_the_models(migrated_url):
    assert drift(migrated_url, Base.metadata) == []


def test_a_model_change_without_a_migration_is_seen(migrated_url):
    changed = MetaData()
    for table in Base.metadata.sorted_tables:
        table.to_metadata(changed)
    changed.tables["meshes"].append_column(Column("colour", Integer, nullable=True))
    Table("audit_trail", changed, Column("id", Integer, primary_key=True))
    diffs = {d[0]: d for d in drift(migrated_url, changed)}
    assert sorted(diffs) == ["add_column", "add_table"]
    assert diffs["add_table"][1].name == "audit_trail"
    assert (diffs["add_column"][2], diffs["add_column"][3].name) == ("meshes", "colour")
