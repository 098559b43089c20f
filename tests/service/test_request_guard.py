"""The request guard on a real uvicorn server (in this process, with one fault-injecting route): an unexpected
error answers a 500 in the one error shape and the keep-alive connection stays open for the next request."""

from __future__ import annotations

import http.client
import json
import threading
import time

import pytest
import uvicorn

from pdeanim_service.api.app import create_app
from pdeanim_service.settings import Settings

from .conftest import free_port


@pytest.fixture
def server(tmp_path):
    app = create_app(Settings(data_dir=tmp_path / "data"))

    @app.get("/boom", include_in_schema=False)
    def boom() -> dict:  # the injected fault
        raise RuntimeError("injected")

    @app.get("/huge", include_in_schema=False)
    def huge() -> dict:  # an allocation no machine grants (8 PiB), failing as under a memory limit
        import numpy as np

        return {"n": np.empty((1 << 20, 1 << 20, 1 << 10)).size}

    port = free_port()
    srv = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="critical"))
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not srv.started and time.monotonic() < deadline:
        time.sleep(0.05)
    assert srv.started
    yield port
    srv.should_exit = True
    thread.join(30)


def test_unexpected_error_keeps_the_connection(server):
    conn = http.client.HTTPConnection("127.0.0.1", server, timeout=30)
    conn.request("GET", "/boom")
    sock = conn.sock
    r = conn.getresponse()
    body = json.loads(r.read())
    assert r.status == 500
    assert body == {"error": {"code": "internal", "message": "internal error (RuntimeError)"}}
    assert not r.will_close
    conn.request("GET", "/openapi.json")
    assert conn.sock is sock, "the server closed the connection after the 500"
    r = conn.getresponse()
    assert r.status == 200 and json.loads(r.read())["info"]["title"] == "pdeanim"
    conn.close()


def test_out_of_memory_answers_503_naming_the_allocation(server):
    conn = http.client.HTTPConnection("127.0.0.1", server, timeout=30)
    conn.request("GET", "/huge")
    r = conn.getresponse()
    body = json.loads(r.read())
    assert r.status == 503 and r.getheader("Retry-After") == "5", body
    assert body["error"]["code"] == "out_of_memory"
    assert body["error"]["message"].startswith("out of memory: allocating 8388608.00 GiB"), body
    conn.close()
