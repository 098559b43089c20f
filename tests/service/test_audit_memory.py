"""Audit defect 6 (memory): a fit whose estimated memory is over the job's memory limit is refused with a
clear message at submission (413), and by the worker at once (one attempt, no retries) when only the
worker's machine is too small, instead of running for minutes into the limit."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh

from pdeanim.fit.budget import fit_memory_bytes

from .conftest import Backend
from .harness import Services, client, make_key, wait_job


@pytest.fixture
def svc(tmp_path):
    s = Services(Backend("sqlite", {"PDEANIM_DATA_DIR": str(tmp_path / "data")}), tmp_path)
    s.start_server()  # default limit: half this machine's memory, enough for the fit below
    # a worker whose per-job limit is half the estimate of the fit below (whatever the estimate's model)
    s.env_extra["PDEANIM_JOB_MEMORY_BYTES"] = str(fit_memory_bytes(1000, 10242) // 2)
    s.start_worker()
    yield s
    s.stop()


def test_fit_over_the_memory_limit_is_refused_at_once(svc):
    sphere = trimesh.creation.icosphere(5)  # 10,242 vertices
    obj = io.BytesIO()
    sphere.export(obj, file_type="obj")
    poses = io.BytesIO()
    np.savez_compressed(poses, vertices=np.zeros((1000, len(sphere.vertices), 3), np.float32))
    key = make_key(svc.backend, "t")
    with client(svc, key) as api:
        mesh = api.post("/v1/meshes", files={"file": ("ball.obj", obj.getvalue())}).json()
        r = api.post(f"/v1/meshes/{mesh['id']}/poses", files={"file": ("p.npz", poses.getvalue())})
        assert r.status_code == 201, r.text
        poses_id = r.json()["id"]
        job = api.post("/v1/jobs", json={"kind": "fit", "poses_id": poses_id}).json()
        done = wait_job(api, job["id"], timeout=120)
        assert done["state"] == "failed" and done["attempt"] == 1, done
        assert done["error"]["code"] == "limit_exceeded", done
        message = done["error"]["message"]
        assert "1000 frames x 10242 vertices" in message and "PDEANIM_JOB_MEMORY_BYTES" in message, message
        svc.server.terminate()
        svc.server.wait(30)
        svc.start_server()  # now the API has the same limit too: refused at submission
    with client(svc, key) as api:
        r = api.post("/v1/jobs", json={"kind": "fit", "poses_id": poses_id})
        assert r.status_code == 413 and r.json()["error"]["code"] == "limit_exceeded", r.text
        assert "1000 frames x 10242 vertices" in r.json()["error"]["message"]
