"""The upload routes in the races of the audit (issue 34), each forced with an injected pause: another tenant
deleting the last row that names the same bytes while an upload stores them (the 201 must stay readable),
and a mesh deleted while poses for it are uploaded (404, nothing left behind; never a 500 IntegrityError or
a 422 naming an internal key). ``test_blob_races.py`` races the same functions many times."""

from __future__ import annotations

import io
import threading

import numpy as np
import pytest
from fastapi.testclient import TestClient

from pdeanim_service.api import app as app_module
from pdeanim_service.api.routes import poses as poses_route
from pdeanim_service.store import lifecycle
from pdeanim_service.store.blobrefs import named
from pdeanim_service.store.context import Store
from pdeanim_service.store.models import Mesh
from pdeanim_service.store.tenants import create_key

TET_OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def _poses_npz(frames: int = 3) -> bytes:
    """Poses of the tetrahedron without faces (the validator then reads the mesh's own blob for them)."""
    vertices = np.random.default_rng(3).normal(size=(frames, 4, 3)).astype(np.float32)
    out = io.BytesIO()
    np.savez(out, vertices=vertices)
    return out.getvalue()


@pytest.fixture
def world(backend):
    """An in-process app on the backend, and clients of two tenants."""
    settings = backend.settings(warm_start=False)
    store = Store.open(settings, run_migrations=True)
    with store.sessions() as session:
        keys = {name: create_key(session, name) for name in ("ann", "bob")}
        session.commit()
    app = app_module.create_app(settings, store=store)
    with TestClient(app) as base:
        clients = {name: TestClient(app, headers={"Authorization": f"Bearer {k}"})
                   for name, (k, _) in keys.items()}
        yield store, clients, {name: t.id for name, (_, t) in keys.items()}, base
    store.close()


def _orphans(store: Store) -> set[str]:
    stored = set(store.blobs.keys(float("inf")))
    with store.sessions() as s:
        return stored - named(s, sorted(stored))


def test_an_upload_deduplicated_onto_a_blob_being_deleted_stays_readable(world, monkeypatch):
    store, clients, tenants, _ = world
    bob = clients["bob"].post("/v1/meshes", files={"file": ("b.obj", TET_OBJ)}).json()
    real_put, calls = store.blobs.put_file, []

    def put_then_other_tenant_deletes(path, key=None):  # noqa: ANN001, ANN202 - the injected race
        stored = real_put(path, key)
        calls.append(key)
        if len(calls) > 1:  # the route restoring the blob under its lock
            return stored
        gone = lifecycle.delete_mesh(store, bob["id"], tenants["bob"])  # bob's was the last row naming it
        assert gone is not None and gone.blobs_removed == 1 and not store.blobs.exists(stored)
        return stored

    monkeypatch.setattr(store.blobs, "put_file", put_then_other_tenant_deletes)
    r = clients["ann"].post("/v1/meshes", files={"file": ("a.obj", TET_OBJ)})
    assert r.status_code == 201, r.text
    monkeypatch.undo()
    assert len(calls) == 2  # stored, taken by bob's delete, stored again before the row was committed
    got = clients["ann"].get(f"/v1/meshes/{r.json()['id']}/file")
    assert got.status_code == 200 and got.content == TET_OBJ  # restored under the blob's lock
    assert clients["bob"].get(f"/v1/meshes/{bob['id']}").status_code == 404
    assert _orphans(store) == set()


def test_poses_of_a_mesh_deleted_before_their_row_answer_404_and_leave_nothing(world, monkeypatch):
    store, clients, tenants, _ = world
    mesh = clients["ann"].post("/v1/meshes", files={"file": ("m.obj", TET_OBJ)}).json()
    real = poses_route.commit_poses

    def delete_first(store_, key, *args):  # noqa: ANN001, ANN002, ANN202 - the injected race
        assert lifecycle.delete_mesh(store, mesh["id"], tenants["ann"]) is not None
        return real(store_, key, *args)

    monkeypatch.setattr(poses_route, "commit_poses", delete_first)
    r = clients["ann"].post(f"/v1/meshes/{mesh['id']}/poses", files={"file": ("p.npz", _poses_npz())})
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found", r.text
    assert "deleted while the poses were uploaded" in r.json()["error"]["message"]
    assert _orphans(store) == set() and list(store.blobs.keys(float("inf"))) == []


def test_poses_whose_mesh_goes_during_validation_answer_404_not_a_422_naming_a_key(world, monkeypatch):
    store, clients, tenants, _ = world
    mesh = clients["ann"].post("/v1/meshes", files={"file": ("m.obj", TET_OBJ)}).json()
    real = poses_route._owned_mesh

    def owned_then_deleted(*args):  # noqa: ANN002, ANN202 - the mesh goes after the route looked it up
        row = real(*args)
        assert lifecycle.delete_mesh(store, mesh["id"], tenants["ann"]) is not None
        return row

    monkeypatch.setattr(poses_route, "_owned_mesh", owned_then_deleted)
    r = clients["ann"].post(f"/v1/meshes/{mesh['id']}/poses", files={"file": ("p.npz", _poses_npz())})
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found", r.text
    assert "BlobNotFound" not in r.text
    assert list(store.blobs.keys(float("inf"))) == []


def test_concurrent_identical_uploads_and_deletes_of_two_tenants_through_the_routes(world):
    """Both tenants upload the same bytes and delete them again, at once, a few dozen times: every 201 is
    readable until its own delete, and nothing is left at the end."""
    store, clients, _, _ = world
    errors: list[str] = []

    def tenant_loop(name: str) -> None:
        api = clients[name]
        for _ in range(12):
            r = api.post("/v1/meshes", files={"file": ("t.obj", TET_OBJ)})
            if r.status_code != 201:
                errors.append(f"{name} upload {r.status_code} {r.text}")
                continue
            got = api.get(f"/v1/meshes/{r.json()['id']}/file")
            if got.status_code != 200 or got.content != TET_OBJ:
                errors.append(f"{name} lost {r.json()['id']}: {got.status_code} {got.text[:200]}")
            api.delete(f"/v1/meshes/{r.json()['id']}")

    threads = [threading.Thread(target=tenant_loop, args=(name,)) for name in clients]
    for t in threads:
        t.start()
    for t in threads:
        t.join(300)
    assert errors == []
    assert list(store.blobs.keys(float("inf"))) == []
    with store.sessions() as s:
        assert s.query(Mesh).count() == 0
