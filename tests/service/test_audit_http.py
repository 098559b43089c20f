"""The audit's reproducers through real HTTP (a real ``pdeanim serve``): each answers a 4xx in the one error
shape, and the keep-alive connection still serves the next request afterwards."""

from __future__ import annotations

import http.client
import io
import json
import uuid

import numpy as np
import pytest

from tests.robustness.test_audit_npz import declared_only, patch_local_and_central, zeros_bomb

from .harness import Services, client, make_key

TETRA = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"


@pytest.fixture(scope="module")
def services(tmp_path_factory):
    from .conftest import Backend

    data = tmp_path_factory.mktemp("data")
    svc = Services(Backend("sqlite", {"PDEANIM_DATA_DIR": str(data)}), tmp_path_factory.mktemp("svc"),
                   env_extra={"PDEANIM_MAX_JSON_BYTES": "200000", "PDEANIM_MAX_HEADER_BYTES": "16384"})
    svc.start_server()
    yield svc
    svc.stop()


@pytest.fixture(scope="module")
def key(services) -> str:
    return make_key(services.backend, "audit")


@pytest.fixture(scope="module")
def api(services, key):
    with client(services, key) as c:
        yield c


class Raw:
    """One persistent HTTP/1.1 connection sending hand-made bodies; notices when the server drops it."""

    def __init__(self, services: Services, key: str):
        self.conn = http.client.HTTPConnection("127.0.0.1", services.port, timeout=60)
        self.key = key
        self.sock = None

    def request(self, method: str, path: str, body: bytes = b"",
                headers: dict | None = None) -> tuple[int, dict]:
        auth = {"Authorization": f"Bearer {self.key}"}
        self.conn.request(method, path, body=body, headers={**auth, **(headers or {})})
        if self.sock is None:
            self.sock = self.conn.sock
        assert self.conn.sock is self.sock, "the server closed the keep-alive connection"
        r = self.conn.getresponse()
        data = r.read()
        assert not r.will_close, f"the server asked to close the connection after {r.status}: {data[:300]!r}"
        return r.status, json.loads(data) if data else {}

    def upload(self, path: str, filename: bytes, data: bytes, extra: dict[bytes, bytes] | None = None):
        boundary = uuid.uuid4().hex.encode()
        disposition = b"\r\nContent-Disposition: form-data; name=\""
        parts = [b"--" + boundary + disposition + name + b"\"\r\n\r\n" + value + b"\r\n"
                 for name, value in (extra or {}).items()]
        parts.append(b"--" + boundary + disposition + b"file\"; filename=\"" + filename
                     + b"\"\r\nContent-Type: application/octet-stream\r\n\r\n" + data + b"\r\n")
        body = b"".join(parts) + b"--" + boundary + b"--\r\n"
        ctype = "multipart/form-data; boundary=" + boundary.decode()
        return self.request("POST", path, body, {"Content-Type": ctype})

    def close(self) -> None:
        self.conn.close()


@pytest.fixture
def raw(services, key):
    r = Raw(services, key)
    yield r
    r.close()


def test_non_ascii_multipart_names(raw):
    """Defect 2: UTF-8 filenames outside Latin-1, accented ones and an extra field named 'é' are accepted and
    stored as sent, on the mesh and poses routes, and the same connection then serves the next request."""
    status, body = raw.upload("/v1/meshes", "日本.obj".encode(), TETRA)
    assert status == 201, body
    assert body["filename"] == "日本.obj"
    status, body = raw.upload("/v1/meshes", "café.obj".encode(), TETRA, {"é".encode(): b"x"})
    assert status == 201, body
    assert body["filename"] == "café.obj"
    mesh_id = body["id"]
    poses = io.BytesIO()
    np.savez(poses, vertices=np.zeros((2, 4, 3), np.float32) + np.arange(4)[:, None])
    status, body = raw.upload(f"/v1/meshes/{mesh_id}/poses", "ポーズ.npz".encode(), poses.getvalue(),
                              {"é".encode(): b"y"})
    assert status == 201, body
    status, body = raw.request("GET", f"/v1/meshes/{mesh_id}")
    assert status == 200 and body["id"] == mesh_id


def error_of(status: int, body: dict, expected: int) -> str:
    assert status == expected, body
    assert set(body) == {"error"} and set(body["error"]) == {"code", "message"} and body["error"]["message"]
    return body["error"]["code"]


def test_poses_reproducers_answer_4xx(raw):
    """Defects 1 and 3 over HTTP: the bomb is a 413, the malformed archives are 422, on one connection."""
    status, mesh = raw.upload("/v1/meshes", b"t.obj", TETRA)
    assert status == 201
    path = f"/v1/meshes/{mesh['id']}/poses"
    good = io.BytesIO()
    np.savez_compressed(good, vertices=np.zeros((2, 4, 3), np.float32))
    cases = [(zeros_bomb((3000, 2930, 3)), 413),  # 3000 frames > the default 2000-frame limit
             (patch_local_and_central(good.getvalue(), 8, "<H", 99), 422),
             (patch_local_and_central(good.getvalue(), 6, "<H", 1), 422),
             (declared_only((100_000_000, 2930, 3)), 413)]
    for blob, expected in cases:
        error_of(*raw.upload(path, b"p.npz", blob), expected)
    assert raw.request("GET", "/healthz")[0] == 200


def test_json_body_and_header_limits(api):
    """Defect 5: a job body over PDEANIM_MAX_JSON_BYTES (declared or chunked) is a 413 before it is parsed,
    and headers over PDEANIM_MAX_HEADER_BYTES are a 431."""
    boxes = [{"box": [0, 0, 0, 1, 1, 1]}] * 100_000
    body = json.dumps({"kind": "simulate", "mesh_id": "mesh_x", "params": {"pins": boxes}}).encode()
    r = api.post("/v1/jobs", content=body, headers={"Content-Type": "application/json"})
    assert error_of(r.status_code, r.json(), 413) == "payload_too_large"
    assert "PDEANIM_MAX_JSON_BYTES" in r.json()["error"]["message"]

    def chunks():
        for i in range(0, len(body), 65536):
            yield body[i:i + 65536]

    r = api.post("/v1/jobs", content=chunks(), headers={"Content-Type": "application/json"})
    assert error_of(r.status_code, r.json(), 413) == "payload_too_large"
    r = api.get("/v1/meshes/nope", headers={"X-Padding": "a" * 20_000})
    assert error_of(r.status_code, r.json(), 431) == "request_header_fields_too_large"


def test_access_log_and_listen_line(services, api):
    """Operations: the server says where it listens and logs one line per request with the tenant."""
    import time

    marker = f"/v1/meshes/nope-{uuid.uuid4().hex[:8]}"
    assert api.get(marker).status_code == 404
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        text = (services.log_dir / "server.log").read_text()
        if marker in text:
            break
        time.sleep(0.1)
    assert f"listening on http://127.0.0.1:{services.port}" in text
    line = next(line for line in text.splitlines() if marker in line)
    assert f"GET {marker} 404" in line and "ms tenant=" in line and "tenant=-" not in line, line


def test_work_limits_at_submission(api):
    """Defect 5: a simulation over the work budget is refused at submission (413, with what to lower), by the
    same estimate the simulator checks; more pins than the bound are a 422 before each is validated; an old
    body with ``seed`` (defect 8: the parameter is gone) is still accepted."""
    r = api.post("/v1/meshes", files={"file": ("t.obj", TETRA, "application/octet-stream")})
    mesh_id = r.json()["id"]
    r = api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh_id,
                                   "params": {"frames": 2000, "substeps": 400, "iterations": 50}})
    assert error_of(r.status_code, r.json(), 413) == "limit_exceeded"
    message = r.json()["error"]["message"]
    assert "simulation work" in message and "lower frames" in message
    r = api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh_id,
                                   "params": {"pins": [{"box": [0, 0, 0, 1, 1, 1]}] * 300}})
    assert error_of(r.status_code, r.json(), 422) == "invalid_parameter"
    assert "at most 256 pins" in r.json()["error"]["message"]
    old_body = {"kind": "simulate", "mesh_id": mesh_id, "params": {"frames": 3, "seed": 7}}
    r = api.post("/v1/jobs", json=old_body)
    assert r.status_code == 202, r.text
    assert "seed" not in r.json()["params"]["params"]


def test_upload_waiting_on_the_database_does_not_stall_other_requests(services, api):
    """Defect 8: while an upload waits for the SQLite write lock (held here by another connection), reads on
    the same API process keep answering: the upload routes do their database work off the event loop."""
    import sqlite3
    import threading
    import time
    from pathlib import Path

    mesh_id = api.post("/v1/meshes", files={"file": ("t.obj", TETRA)}).json()["id"]
    path = Path(services.backend.env["PDEANIM_DATA_DIR"]) / "pdeanim.sqlite3"
    db = sqlite3.connect(path, isolation_level=None)
    db.execute("BEGIN IMMEDIATE")  # the write lock: the upload's INSERT waits (busy timeout 30 s)
    results: list = []
    uploader = threading.Thread(target=lambda: results.append(
        api.post("/v1/meshes", files={"file": ("u.obj", TETRA)})))
    try:
        uploader.start()
        started, slowest = time.monotonic(), 0.0
        while time.monotonic() - started < 4.0:  # the tiny upload reaches its INSERT well within this window
            t = time.monotonic()
            assert api.get(f"/v1/meshes/{mesh_id}").status_code == 200
            slowest = max(slowest, time.monotonic() - t)
    finally:
        db.rollback()
        db.close()
    uploader.join(60)
    assert results and results[0].status_code == 201, results
    # a blocked event loop makes the reads wait for the lock (~4 s); unblocked reads take milliseconds, and
    # 1.5 s leaves room for a loaded machine
    assert slowest < 1.5, slowest
