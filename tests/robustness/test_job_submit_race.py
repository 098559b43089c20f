"""Submitting a job while another process writes to the SQLite database must not answer 500 ("database is
locked")."""

from __future__ import annotations

import sqlite3

import pytest
from fastapi.testclient import TestClient

from pdeanim_service.api import app as app_module
from pdeanim_service.api.routes import jobs as jobs_route
from pdeanim_service.settings import Settings
from pdeanim_service.store.context import Store
from pdeanim_service.store.tenants import create_key

SPHERE_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


@pytest.fixture
def client_and_db(tmp_path):
    settings = Settings(data_dir=tmp_path / "data")
    store = Store.open(settings, run_migrations=True)
    with store.sessions() as session:
        key, _ = create_key(session, "race")
        session.commit()
    app = app_module.create_app(settings, store=store)
    with TestClient(app, headers={"Authorization": f"Bearer {key}"}) as client:
        yield client, settings.resolved_database_url().removeprefix("sqlite:///")
    store.close()


def test_job_submission_survives_a_concurrent_write(client_and_db, monkeypatch) -> None:
    """A worker committing between the route's reads and its insert (injected here) must not make it fail."""
    client, db_path = client_and_db
    r = client.post("/v1/meshes", files={"file": ("tet.obj", SPHERE_OBJ.encode())})
    assert r.status_code == 201, r.text
    mesh_id = r.json()["id"]
    real = jobs_route.normalize_request

    def write_meanwhile(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        other = sqlite3.connect(db_path, timeout=5)
        other.execute("UPDATE meshes SET filename = 'renamed.obj' WHERE id = ?", (mesh_id,))
        other.commit()
        other.close()
        return real(*args, **kwargs)

    monkeypatch.setattr(jobs_route, "normalize_request", write_meanwhile)
    r = client.post("/v1/jobs", json={"kind": "cyclic", "mesh_id": mesh_id, "params": {"mode": "eel"}})
    assert r.status_code == 202, r.text
    assert r.json()["state"] == "queued"
