"""Audit defect 6 (memory): a fit whose estimated memory is over the job's memory limit is refused at once with
a clear message (one attempt, no retries), instead of running for minutes into the limit."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh

from .conftest import Backend
from .harness import Services, client, make_key, wait_job

pytestmark = pytest.mark.slow


@pytest.fixture
def svc(tmp_path):
    s = Services(Backend("sqlite", {"PDEANIM_DATA_DIR": str(tmp_path / "data")}), tmp_path,
                 env_extra={"PDEANIM_JOB_MEMORY_BYTES": str(2 * 1024**3)})
    s.start_server()
    s.start_worker()
    yield s
    s.stop()


def test_fit_over_the_memory_limit_is_refused_at_once(svc):
    sphere = trimesh.creation.icosphere(5)  # 10,242 vertices
    obj = io.BytesIO()
    sphere.export(obj, file_type="obj")
    poses = io.BytesIO()
    np.savez_compressed(poses, vertices=np.zeros((1000, len(sphere.vertices), 3), np.float32))
    with client(svc, make_key(svc.backend, "t")) as api:
        mesh = api.post("/v1/meshes", files={"file": ("ball.obj", obj.getvalue())}).json()
        r = api.post(f"/v1/meshes/{mesh['id']}/poses", files={"file": ("p.npz", poses.getvalue())})
        assert r.status_code == 201, r.text
        job = api.post("/v1/jobs", json={"kind": "fit", "poses_id": r.json()["id"]}).json()
        done = wait_job(api, job["id"], timeout=120)
    assert done["state"] == "failed" and done["attempt"] == 1, done
    assert done["error"]["code"] == "limit_exceeded", done
    message = done["error"]["message"]
    assert "1000 frames x 10242 vertices" in message and "PDEANIM_JOB_MEMORY_BYTES" in message, message
