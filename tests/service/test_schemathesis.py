"""schemathesis over the committed ``openapi/openapi.json`` against a real ``pdeanim serve`` with a real key:
every check (``--checks all``), at least 2000 generated requests, no 5xx and no undocumented status."""

from __future__ import annotations

import io
import os
import re
import signal
import subprocess
import sys

import httpx
import numpy as np
import pytest

from .conftest import open_backend
from .harness import ROOT, Services, make_key, wait_job

MIN_REQUESTS = 2000
CYCLIC = {"mode": "eel", "frames": 12, "n_curves": 21, "points": 24, "modes": 4}
BUDGET_SECONDS = 150  # the fuzzing and stateful phases repeat until this is spent (about 3000+ cases here)
CI_BUDGET_SECONDS, CI_MIN_REQUESTS = 30, 150  # the run CI makes (the full one is benchmark-sized: nightly)
# One worker: with two threads, hypothesis's ast.parse of filter lambdas (inside schemathesis) can crash on
# CPython 3.11 ("AST constructor recursion depth mismatch", a thread-safety bug in the AST constructor).
WORKERS = "1"


@pytest.fixture
def services(tmp_path, request):
    """The server on the embedded backend (the routes are the same on PostgreSQL; the run takes minutes)."""
    with open_backend("sqlite", tmp_path / "data", request) as backend:
        # short long-polls: generated ?wait= values would otherwise hold each request for the default 30 s
        svc = Services(backend, tmp_path, env_extra={"PDEANIM_MAX_WAIT_SECONDS": "0.5",
                                                     "PDEANIM_MAX_UPLOAD_BYTES": "2000000"})
        svc.start_server()
        try:
            yield svc
        finally:
            svc.stop()


def seed(services: Services, key: str) -> dict[str, str]:
    """A mesh, poses of it, and a finished cyclic job with its clip (one worker, stopped before the run)."""
    from pdeanim.mesh.io import load_mesh

    obj = (ROOT / "tests/data/fish_eel.obj").read_bytes()
    api = httpx.Client(base_url=services.url, headers={"Authorization": f"Bearer {key}"}, timeout=60)
    mesh = api.post("/v1/meshes", files={"file": ("fish.obj", obj)}).json()
    verts = load_mesh(obj, filename="fish.obj").vertices
    buf = io.BytesIO()
    np.savez(buf, vertices=np.stack([verts, verts * 1.01, verts * 1.02]).astype(np.float32))
    poses = api.post(f"/v1/meshes/{mesh['id']}/poses", files={"file": ("p.npz", buf.getvalue())}).json()
    job = api.post("/v1/jobs", json={"kind": "cyclic", "mesh_id": mesh["id"], "params": CYCLIC}).json()
    worker = services.start_worker()
    job = wait_job(api, job["id"], timeout=240)
    worker.send_signal(signal.SIGTERM)
    worker.wait(60)
    assert job["state"] == "succeeded", (job, services.logs())
    return {"FUZZ_MESH_ID": mesh["id"], "FUZZ_POSES_ID": poses["id"],
            "FUZZ_CLIP_ID": job["result"]["clip_id"], "FUZZ_JOB_ID": job["id"]}


@pytest.mark.parametrize(("budget", "min_requests"), [
    pytest.param(CI_BUDGET_SECONDS, CI_MIN_REQUESTS, id="ci"),
    pytest.param(BUDGET_SECONDS, MIN_REQUESTS, marks=pytest.mark.slow, id="full")])
def test_schemathesis_finds_no_server_error_and_no_undocumented_status(services, tmp_path, budget,
                                                                        min_requests):
    key = make_key(services.backend, "fuzz")
    cmd = [sys.executable, "-m", "schemathesis.cli", "--config-file",
           str(ROOT / "tests/service/schemathesis.toml"), "run", str(ROOT / "openapi/openapi.json"),
           "--url", services.url, "-H", f"Authorization: Bearer {key}",
           "--checks", "all", "--max-examples", "25", "--workers", WORKERS, "--max-time", str(budget),
           "--seed", "20261126", "--generation-database", "none", "--no-color"]
    env = {**os.environ, **seed(services, key)}
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=budget * 4 + 120, cwd=tmp_path,
                         env=env)
    report = out.stdout + out.stderr
    generated = re.search(r"(\d+) generated", report)
    assert out.returncode == 0, report[-12000:] + "\n" + services.logs()[-4000:]
    assert generated and int(generated.group(1)) >= min_requests, report[-3000:]
    print(report[report.find("Test cases:"):][:200])  # the count, for -s runs
    assert "Traceback" not in services.logs(), services.logs()[-4000:]
