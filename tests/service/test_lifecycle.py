"""Lifecycle through real HTTP: list with cursor pages and filters, delete a mesh or a clip (blobs removed
once unreferenced), cancel queued and running jobs, long-poll a job, Location headers, ``pdeanim keys
list/revoke``, and choosing the animation of a glTF upload (API and ``pdeanim fit --animation``)."""

from __future__ import annotations

import concurrent.futures
import io
import json
import os
import subprocess
import time

import httpx
import numpy as np
import pytest

from pdeanim_service.store.context import Store

from .conftest import running_services
from .harness import PDEANIM, ROOT, Services, client, make_key, process_env, wait_job

POSTGRES_NIGHTLY = True  # routes over the store (keys, long polls): CI runs them on SQLite (conftest)

CYCLIC = {"mode": "eel", "frames": 12, "n_curves": 21, "points": 24, "modes": 4}
LONG_SIM = {"frames": 2000, "target_tets": 600, "substeps": 20, "iterations": 8}  # tens of seconds even idle
OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"


@pytest.fixture(scope="module")
def services(module_backend, tmp_path_factory):
    yield from running_services(module_backend, tmp_path_factory.mktemp("svc"),
                                {"PDEANIM_MAX_WAIT_SECONDS": "20"})


@pytest.fixture(scope="module")
def store(services):
    st = Store.open(services.backend.settings())
    yield st
    st.close()


def upload(api, name: str, data: bytes, path: str = "/v1/meshes"):
    return api.post(path, files={"file": (name, data, "application/octet-stream")})


def cyclic_clip(api, services, mesh_id: str, **params) -> dict:
    r = api.post("/v1/jobs", json={"kind": "cyclic", "mesh_id": mesh_id, "params": {**CYCLIC, **params}})
    assert r.status_code == 202, r.text
    job = wait_job(api, r.json()["id"], timeout=240)
    assert job["state"] == "succeeded", (job, services.logs())
    return job


def every_page(api, path: str, **params) -> list[dict]:
    items, cursor, pages = [], None, 0
    while True:
        r = api.get(path, params={**params, **({"cursor": cursor} if cursor else {})})
        assert r.status_code == 200, r.text
        items += r.json()["items"]
        cursor, pages = r.json()["next_cursor"], pages + 1
        if cursor is None:
            return items
        assert pages < 100


def test_location_headers_and_lists_with_cursor_pages(api, other, data_dir):
    ids = []
    for i in range(5):
        r = upload(api, f"tet{i}.obj", OBJ + f"# copy {i}\n".encode())
        assert r.status_code == 201, r.text
        assert r.headers["location"] == f"/v1/meshes/{r.json()['id']}"
        assert api.get(r.headers["location"]).json()["id"] == r.json()["id"]
        ids.append(r.json()["id"])
    first = api.get("/v1/meshes", params={"limit": 2}).json()
    assert len(first["items"]) == 2 and first["next_cursor"]
    listed = [m["id"] for m in every_page(api, "/v1/meshes", limit=2)]
    assert len(listed) == len(set(listed)) and set(ids) <= set(listed)
    assert [i for i in listed if i in ids] == ids[::-1]  # newest first
    assert not set(ids) & {m["id"] for m in every_page(other, "/v1/meshes")}  # tenants see only their own
    r = api.get("/v1/meshes", params={"cursor": "bm90LWEtY3Vyc29y"})
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_cursor"
    assert api.get("/v1/meshes", params={"limit": 0}).status_code == 422


def test_jobs_and_poses_lists_filter(api, services, data_dir):
    fish = upload(api, "fish_eel.obj", (data_dir / "fish_eel.obj").read_bytes()).json()
    r = api.post("/v1/jobs", json={"kind": "cyclic", "mesh_id": fish["id"], "params": CYCLIC})
    assert r.status_code == 202 and r.headers["location"] == f"/v1/jobs/{r.json()['id']}"
    job = wait_job(api, r.json()["id"], timeout=240)
    assert job["state"] == "succeeded", (job, services.logs())
    mine = every_page(api, "/v1/jobs", mesh_id=fish["id"])
    assert [j["id"] for j in mine] == [job["id"]]
    assert job["id"] in {j["id"] for j in every_page(api, "/v1/jobs", state="succeeded", kind="cyclic")}
    assert job["id"] not in {j["id"] for j in every_page(api, "/v1/jobs", state="queued")}
    assert job["id"] not in {j["id"] for j in every_page(api, "/v1/jobs", kind="fit")}
    clips = every_page(api, "/v1/clips", mesh_id=fish["id"])
    assert [c["id"] for c in clips] == [job["result"]["clip_id"]]
    same_kind = every_page(api, "/v1/clips", kind=clips[0]["kind"], mesh_id=fish["id"])
    assert [c["id"] for c in same_kind] == [clips[0]["id"]]
    assert clips[0]["kind"] == "cyclic-spine"
    other_kind = every_page(api, "/v1/clips", kind="dynamic-pde", mesh_id=fish["id"])
    assert other_kind == []
    for path, params in (("/v1/clips", {"kind": "bogus"}), ("/v1/jobs", {"kind": "bogus"}),
                         ("/v1/jobs", {"state": "bogus"})):  # an unknown filter value is a 422 on every list
        r = api.get(path, params=params)
        assert r.status_code == 422 and r.json()["error"]["code"] == "validation_error", (path, r.text)
    assert api.get("/v1/jobs", params={"kind": "export"}).status_code == 200
    assert every_page(api, "/v1/poses", mesh_id=fish["id"]) == []


def _blob_exists(store: Store, key: str) -> bool:
    return store.blobs.exists(key)


def test_delete_mesh_cascades_and_removes_only_unreferenced_blobs(api, other, services, store, data_dir):
    data = (data_dir / "fish_eel.obj").read_bytes() + b"# a file only this test uploads\n"
    a, b = upload(api, "a.obj", data).json(), upload(other, "b.obj", data).json()  # one shared blob
    job = cyclic_clip(api, services, a["id"], frames=10)  # a clip no other test makes (blobs are shared)
    clip_id = job["result"]["clip_id"]
    with store.sessions() as s:
        from pdeanim_service.store.models import ClipRecord, Mesh

        mesh_key = s.get(Mesh, a["id"]).blob_key
        clip = s.get(ClipRecord, clip_id)
        clip_keys = [clip.topology_key, clip.coefficients_key]
    assert api.get(f"/v1/clips/{clip_id}/frame", params={"t": 0.5}).status_code == 200  # now cached
    assert other.delete(f"/v1/meshes/{a['id']}").status_code == 404  # not theirs
    r = api.delete(f"/v1/meshes/{a['id']}")
    assert r.status_code == 200, r.text
    assert r.json()["meshes"] == 1 and r.json()["clips"] == 1 and r.json()["jobs"] == 1
    for path in (f"/v1/meshes/{a['id']}", f"/v1/clips/{clip_id}", f"/v1/jobs/{job['id']}",
                 f"/v1/clips/{clip_id}/frame?t=0.5", f"/v1/meshes/{a['id']}/topology"):
        assert api.get(path).status_code == 404, path
    assert api.delete(f"/v1/meshes/{a['id']}").status_code == 404
    assert _blob_exists(store, mesh_key)  # still the other tenant's mesh
    assert not _blob_exists(store, clip_keys[1])  # coefficients: this clip's only
    assert _blob_exists(store, clip_keys[0])  # topology: shared with the fish clip of an earlier test
    assert other.get(f"/v1/meshes/{b['id']}").status_code == 200
    assert other.delete(f"/v1/meshes/{b['id']}").json()["blobs_removed"] == 1
    assert not _blob_exists(store, mesh_key)


def test_delete_clip_keeps_blobs_another_clip_uses(api, services, store, data_dir):
    mesh = upload(api, "fish.obj", (data_dir / "fish_eel.obj").read_bytes()).json()
    one, two = (cyclic_clip(api, services, mesh["id"], frames=8)["result"]["clip_id"] for _ in range(2))
    with store.sessions() as s:
        from pdeanim_service.store.models import ClipRecord

        keys = {s.get(ClipRecord, one).coefficients_key, s.get(ClipRecord, two).coefficients_key}
    assert len(keys) == 1  # same input, deterministic output: one shared coefficients blob
    r = api.delete(f"/v1/clips/{one}")
    assert r.status_code == 200 and r.json()["clips"] == 1 and r.json()["blobs_removed"] == 0, r.text
    assert api.get(f"/v1/clips/{one}").status_code == 404
    assert api.get(f"/v1/clips/{two}/frame", params={"t": 0.25}).status_code == 200
    # the topology blob is shared with fish clips of other tests when they ran
    assert api.delete(f"/v1/clips/{two}").json()["blobs_removed"] in (1, 2)
    assert not any(_blob_exists(store, k) for k in keys)
    assert api.get(f"/v1/meshes/{mesh['id']}").status_code == 200


def test_cancel_running_job_stops_its_worker_and_long_poll_sees_changes(api, services, data_dir):
    mesh = upload(api, "spot.obj", (data_dir / "spot.obj").read_bytes()).json()
    r = api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh["id"], "params": LONG_SIM})
    assert r.status_code == 202, r.text
    job = r.json()
    deadline = time.monotonic() + 120
    while job["state"] == "queued" and time.monotonic() < deadline:
        started = time.monotonic()
        job = api.get(f"/v1/jobs/{job['id']}", params={"wait": 10}).json()  # answers on the state change
        assert time.monotonic() - started < 20  # bounded by the wait, plus slack for this loaded machine
    assert job["state"] == "running", job
    r = api.post(f"/v1/jobs/{job['id']}/cancel")
    assert r.status_code == 200 and r.json()["state"] == "cancelled", r.text
    assert api.post(f"/v1/jobs/{job['id']}/cancel").json()["state"] == "cancelled"  # idempotent
    started = time.monotonic()
    assert api.get(f"/v1/jobs/{job['id']}", params={"wait": 15}).json()["state"] == "cancelled"
    assert time.monotonic() - started < 5  # a finished job answers at once
    # the worker stops the attempt at its next heartbeat (lease 3 s: every second) and takes the next job
    fish = upload(api, "f.obj", (data_dir / "fish_eel.obj").read_bytes()).json()
    nxt = cyclic_clip(api, services, fish["id"])
    assert nxt["state"] == "succeeded"
    final = api.get(f"/v1/jobs/{job['id']}").json()
    assert final["state"] == "cancelled" and final["result"].get("poses_id") is None, final
    assert f"job {job['id']} was cancelled or deleted" in services.logs()


def test_cancel_queued_job_and_finished_job(api, services, data_dir):
    mesh = upload(api, "spot.obj", (data_dir / "spot.obj").read_bytes()).json()
    blocker = api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh["id"],
                                         "params": LONG_SIM}).json()
    queued = api.post("/v1/jobs", json={"kind": "cyclic", "mesh_id": mesh["id"], "params": CYCLIC}).json()
    r = api.post(f"/v1/jobs/{queued['id']}/cancel")
    assert r.status_code == 200 and r.json()["state"] == "cancelled", r.text
    assert api.post(f"/v1/jobs/{blocker['id']}/cancel").json()["state"] == "cancelled"
    fish = upload(api, "f.obj", (data_dir / "fish_eel.obj").read_bytes()).json()
    done = cyclic_clip(api, services, fish["id"])
    assert api.get(f"/v1/jobs/{queued['id']}").json()["attempt"] == 0  # never claimed
    r = api.post(f"/v1/jobs/{done['id']}/cancel")
    assert r.status_code == 409 and r.json()["error"]["code"] == "conflict"
    assert api.post("/v1/jobs/job_nope/cancel").status_code == 404


def test_long_poll_is_bounded_and_does_not_block_other_requests(api, services, data_dir):
    mesh = upload(api, "spot.obj", (data_dir / "spot.obj").read_bytes()).json()
    blocker = api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh["id"],
                                         "params": LONG_SIM}).json()
    queued = api.post("/v1/jobs", json={"kind": "cyclic", "mesh_id": mesh["id"], "params": CYCLIC}).json()
    with concurrent.futures.ThreadPoolExecutor(8) as pool:
        started = time.monotonic()
        waits = [pool.submit(httpx.get, f"{services.url}/v1/jobs/{queued['id']}", params={"wait": 600},
                             headers={"Authorization": api.headers["authorization"]}, timeout=120)
                 for _ in range(6)]
        time.sleep(0.5)
        quick = time.monotonic()
        assert api.get("/v1/meshes", params={"limit": 1}).status_code == 200
        assert time.monotonic() - quick < 10  # six open long polls do not stall the server
        answers = [w.result(timeout=120) for w in waits]
    elapsed = time.monotonic() - started
    assert all(a.status_code == 200 for a in answers)
    assert elapsed < 60, elapsed  # capped by PDEANIM_MAX_WAIT_SECONDS=20, not by wait=600
    if all(a.json()["state"] == "queued" for a in answers):  # unchanged: they waited the whole cap
        assert elapsed >= 15, elapsed
    for job in (queued, blocker):
        api.post(f"/v1/jobs/{job['id']}/cancel")


def test_keys_list_and_revoke(services, api):
    env = process_env(services.backend)

    def keys(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(PDEANIM + ["keys", *args], env=env, capture_output=True, text=True, timeout=120)

    key = keys("create", "--tenant", "revokee").stdout.strip()
    listed = keys("list", "--tenant", "revokee")
    assert listed.returncode == 0 and key[:10] in listed.stdout and key not in listed.stdout
    (row,) = json.loads(keys("list", "--tenant", "revokee", "--json").stdout)
    assert row["revoked_at"] is None and row["prefix"] == key[:10]
    assert keys("revoke", "pda").returncode == 2  # too short to name one key
    assert keys("revoke", "key_nope_nope").returncode == 2
    out = keys("revoke", key[:10])
    assert out.returncode == 0 and row["id"] in out.stdout, out.stderr
    assert client(services, key).get("/v1/meshes").status_code == 401
    (row,) = json.loads(keys("list", "--tenant", "revokee", "--json").stdout)
    assert row["revoked_at"] is not None
    assert keys("revoke", row["id"]).returncode == 0  # already revoked: says so, still succeeds
    assert api.get("/v1/meshes").status_code == 200  # other keys unaffected


CLI_ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def two_animation_glb(verts, faces) -> bytes:
    """An animated GLB with two animations, "Idle" (index 0) and "Swim" (index 1; the same channels)."""
    import struct

    from pdeanim.gltf.write import animation_glb

    glb = animation_glb(verts, np.arange(len(verts)) / 30.0, faces)
    (json_len,) = struct.unpack_from("<I", glb, 12)
    doc = json.loads(glb[20:20 + json_len])
    doc["animations"] = [{**doc["animations"][0], "name": "Idle"}, {**doc["animations"][0], "name": "Swim"}]
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    rest = glb[20 + json_len:]
    body = struct.pack("<I", len(text)) + b"JSON" + text + rest
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


@pytest.fixture(scope="module")
def morph(data_dir):
    """A closed morphing sphere (AnimatedMorphSphere's used vertices) as OBJ bytes, frames and faces."""
    d = np.load(data_dir / "AnimatedMorphSphere.npz")
    used = np.unique(d["faces"])
    remap = np.full(len(d["vertices"][0]), -1)
    remap[used] = np.arange(len(used))
    verts, faces = d["vertices"][:8, used], remap[d["faces"]]
    obj = "".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in verts[0]) + "".join(
        f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    return obj.encode(), verts, faces


def test_gltf_upload_chooses_the_animation_and_says_which(api, morph):
    obj, verts, faces = morph
    glb = two_animation_glb(verts, faces)
    mesh = upload(api, "sphere.obj", obj).json()
    path = f"/v1/meshes/{mesh['id']}/poses"
    first = upload(api, "two.glb", glb, path)
    assert first.status_code == 201 and first.json()["animation"] == {"index": 0, "name": "Idle"}, first.text
    swim = upload(api, "two.glb", glb, path + "?animation=Swim")
    assert swim.status_code == 201 and swim.json()["animation"] == {"index": 1, "name": "Swim"}, swim.text
    meta = api.get(f"/v1/poses/{swim.json()['id']}", headers={"Accept": "application/json"}).json()
    assert meta["animation"]["name"] == "Swim"
    assert upload(api, "two.glb", glb, path + "?animation=1").json()["animation"]["index"] == 1
    err = upload(api, "two.glb", glb, path + "?animation=Walk")
    assert err.status_code == 422 and "Idle" in err.json()["error"]["message"], err.text
    buf = io.BytesIO()
    np.savez(buf, vertices=verts)
    err = upload(api, "p.npz", buf.getvalue(), path + "?animation=Swim")
    assert err.status_code == 422 and "glTF" in err.json()["error"]["message"], err.text


def test_cli_fit_takes_animation_by_name(morph, tmp_path):
    _, verts, faces = morph
    (tmp_path / "two.glb").write_bytes(two_animation_glb(verts, faces))
    fit = PDEANIM + ["fit", str(tmp_path / "two.glb"), "--segments", "1", "--quiet"]
    out = subprocess.run(fit + ["--animation", "Swim", "--out", str(tmp_path / "swim.clip")],
                         capture_output=True, text=True, timeout=300, cwd=tmp_path, env=CLI_ENV)
    assert out.returncode == 0, out.stderr
    assert "animation: Swim (index 1)" in out.stdout and (tmp_path / "swim.clip").stat().st_size > 0
    bad = subprocess.run(fit + ["--animation", "Walk", "--out", str(tmp_path / "walk.clip")],
                         capture_output=True, text=True, timeout=300, cwd=tmp_path, env=CLI_ENV)
    assert bad.returncode == 2 and "Walk" in bad.stderr, bad.stderr


def test_clip_list_answers_json_for_old_clips_with_non_finite_errors(api, store):
    """A clip stored before metrics were made finite (report with inf) lists with null (pydantic writes
    non-finite floats as null), not a 500."""
    from sqlalchemy.exc import DBAPIError

    from pdeanim_service.store.models import ClipRecord, Mesh

    mesh = upload(api, "old.obj", OBJ + b"# old clip\n").json()
    with store.sessions() as s:
        tenant = s.get(Mesh, mesh["id"]).tenant_id
        s.add(ClipRecord(id="clip_old_inf", tenant_id=tenant, mesh_id=mesh["id"], kind="dynamic-pde",
                         topology_key="t", coefficients_key="c", topology_id="x" * 64,
                         report={"rel_rms": float("inf"), "errors": {"kg": float("nan")}, "sizes": {"a": 1}}))
        if store.engine.dialect.name != "sqlite":  # such rows cannot exist there: PostgreSQL refuses them
            with pytest.raises(DBAPIError, match="(?i)json|infinity"):
                s.commit()
            return
        s.commit()
    r = api.get("/v1/clips", params={"mesh_id": mesh["id"]})
    assert r.status_code == 200, r.text
    (item,) = r.json()["items"]
    assert item["errors"] == {"rel_rms": None, "kg": None} and item["sizes"] == {"a": 1}
    assert api.delete("/v1/clips/clip_old_inf").status_code == 200


def test_database_outage_answers_503_with_retry_after(tmp_path, request):
    """PostgreSQL's database dropped under a running server: every route answers 503 in the error shape
    (the documented status, with Retry-After), never a 500. Runs once, on its own PostgreSQL database."""
    from .conftest import _admin, open_backend

    with open_backend("postgres", tmp_path / "data", request) as backend:
        svc = Services(backend, tmp_path)
        svc.start_server()
        try:
            with client(svc, make_key(backend, "outage")) as api:
                assert api.get("/v1/meshes").status_code == 200  # the key is now verified (and cached)
                name = backend.env["PDEANIM_DATABASE_URL"].rsplit("/", 1)[1]
                _admin(request.getfixturevalue("pg_server"), f"DROP DATABASE {name} WITH (FORCE)")
                for r in (api.get("/v1/meshes"), api.get("/v1/jobs/job_x"),
                          api.post("/v1/jobs/job_x/cancel")):
                    assert r.status_code == 503, r.text
                    assert r.json()["error"]["code"] == "unavailable" and r.headers["retry-after"] == "5"
                assert httpx.get(svc.url + "/healthz", timeout=30).status_code == 503
        finally:
            svc.stop()


def test_malformed_json_is_400_and_head_answers_like_get(api, services):
    for body in (b"{bad", b'{"kind": "fit"', b"[1, 2"):
        r = api.post("/v1/jobs", content=body, headers={"Content-Type": "application/json"})
        assert r.status_code == 400, r.text
        assert r.json()["error"]["code"] == "bad_request" and "malformed JSON" in r.json()["error"]["message"]
    not_an_object = api.post("/v1/jobs", json=[1, 2])  # well-formed JSON of the wrong shape: 422
    assert not_an_object.status_code == 422, not_an_object.text
    for path in ("/healthz", "/v1/meshes", "/v1/jobs?kind=export", "/viewer"):
        get, head = api.get(path), api.head(path)
        assert head.status_code == get.status_code == 200, (path, head.text)
        assert head.content == b""
        assert head.headers["content-type"] == get.headers["content-type"]
        assert head.headers.get("etag") == get.headers.get("etag")
    assert api.head("/v1/meshes/mesh_nope").status_code == 404
    mesh = upload(api, "tet.obj", OBJ + b"# gravity test\n").json()
    heavy = api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh["id"],
                                       "params": {"gravity": [1e308] * 3}})  # was a ZeroDivisionError x3
    assert heavy.status_code == 422 and heavy.json()["error"]["code"] == "invalid_parameter", heavy.text
    assert "gravity" in heavy.json()["error"]["message"] and "1e+06" in heavy.json()["error"]["message"]
    cancel = api.head("/v1/jobs/job_nope/cancel")  # a POST-only path: 405 naming the methods it has
    assert cancel.status_code == 405 and "POST" in cancel.headers["allow"]
