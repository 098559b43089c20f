"""The service commands as a user runs them: ``pdeanim keys create`` and ``pdeanim demo``."""

from __future__ import annotations

import signal
import subprocess

from .conftest import Backend
from .harness import PDEANIM, Services, client, make_key, process_env, wait_job

POSTGRES_NIGHTLY = True  # CLI over the store: CI runs it on SQLite (conftest)


def test_keys_create_prints_a_working_key(module_backend, tmp_path):
    env = process_env(module_backend)
    out = subprocess.run(
        PDEANIM + ["keys", "create", "--tenant", "cli"], env=env, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    key = out.stdout.strip()
    assert key.startswith("pda_") and len(key) > 40
    svc = Services(module_backend, tmp_path)
    svc.start_server()
    try:
        assert client(svc, key).get("/v1/jobs/job_nope").status_code == 404  # authenticated, then not found
        assert client(svc, key[:-1]).get("/v1/jobs/job_nope").status_code == 401
    finally:
        svc.stop()


def test_demo_runs_end_to_end(tmp_path):
    """The demo always runs on the embedded default (its own data directory)."""
    out = subprocess.run(
        PDEANIM + ["demo", "--out", str(tmp_path / "out"), "--data-dir", str(tmp_path / "data")],
        env=process_env(Backend("sqlite")),
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    for name in ("frame_t0.5.glb", "animation.glb", "poses.npz"):
        assert (tmp_path / "out" / name).read_bytes()[:4] in (b"glTF", b"PK\x03\x04")
    for word in ("sizes:", "coefficients", "fit:", "rel. rms", "timing:", "simulate", "stopped"):
        assert word in out.stdout


def test_serve_with_workers_runs_jobs_and_stops_them(module_backend, tmp_path, data_dir):
    svc = Services(module_backend, tmp_path)
    svc.start_server("--with-workers", "1")
    try:
        api = client(svc, make_key(module_backend, "embedded"))
        mesh = api.post(
            "/v1/meshes", files={"file": ("fish.obj", (data_dir / "fish_capsule.obj").read_bytes())}
        )
        job = api.post(
            "/v1/jobs", json={"kind": "cyclic", "mesh_id": mesh.json()["id"], "params": {"frames": 6}}
        )
        assert wait_job(api, job.json()["id"])["state"] == "succeeded"
    finally:
        svc.server.send_signal(signal.SIGTERM)
        assert svc.server.wait(60) == 0
    log = (tmp_path / "server.log").read_text()
    assert "worker" in log and "stopped after 1 jobs" in log, log
