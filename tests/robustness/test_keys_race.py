"""``pdeanim keys create`` while the service writes to the same SQLite database: a key, not a traceback."""

from __future__ import annotations

import sqlite3

from sqlalchemy import text

import pdeanim_service.store.tenants as tenants
from pdeanim_service.cli import main
from pdeanim_service.settings import Settings
from pdeanim_service.store.context import Store


def _inject_concurrent_write(tmp_path, monkeypatch) -> None:  # noqa: ANN001
    """Make ``create_key`` see a write committed by another process after its transaction began."""
    monkeypatch.setenv("PDEANIM_DATA_DIR", str(tmp_path / "data"))
    store = Store.open(Settings(), run_migrations=True)
    store.close()
    db_path = Settings().resolved_database_url().removeprefix("sqlite:///")
    real = tenants.create_key

    def write_meanwhile(session, name):  # noqa: ANN001, ANN202
        session.execute(text("SELECT count(*) FROM tenants"))  # the command's transaction has begun
        other = sqlite3.connect(db_path, timeout=0.2)
        try:
            other.execute("INSERT INTO tenants (id, name, created_at) VALUES ('t_other', 'other', 0)")
            other.commit()
        except sqlite3.OperationalError:
            pass  # the command holds the write lock: the service would simply wait its turn
        finally:
            other.close()
        return real(session, name)

    monkeypatch.setattr(tenants, "create_key", write_meanwhile)


def test_keys_create_survives_a_concurrent_write(tmp_path, monkeypatch, capsys) -> None:
    """``pdeanim keys create`` prints a key although the service committed meanwhile."""
    _inject_concurrent_write(tmp_path, monkeypatch)
    assert main(["keys", "create", "--tenant", "me"]) == 0
    assert capsys.readouterr().out.strip().startswith("pda_")


def test_issue_key_survives_a_concurrent_write(tmp_path, monkeypatch) -> None:
    """The one key-creation path (the CLI, the demo and the tests use it) called directly."""
    _inject_concurrent_write(tmp_path, monkeypatch)
    key = tenants.issue_key(Settings(), "demo")
    store = Store.open(Settings())
    try:
        with store.sessions() as session:
            assert tenants.tenant_for_key(session, key) is not None
    finally:
        store.close()
