"""A fit in window tasks through real servers and workers (SQLite + local blobs, and PostgreSQL + S3): a
worker killed mid-window (that window alone reruns, the clip is written once and is byte-identical to the
in-process windowed fit), cancel of a windowed job, progress counting windows, and the memory estimate at
submission (the largest task's)."""

from __future__ import annotations

import io
import os
import signal
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import func, select

from pdeanim_service.store import windows
from pdeanim_service.store.context import Store
from pdeanim_service.store.models import ClipRecord, Job

from .harness import Services, client, make_key, wait_job

POSTGRES_NIGHTLY = True  # window tasks via the job route: CI runs them on SQLite (claims: test_window_queue)

HOOK = Path(__file__).parent / "windowhold"
WINDOWS = {"PDEANIM_FIT_WINDOW_FIT_VALUES": "100000", "PDEANIM_FIT_WINDOW_VALUES": "75000"}
OPTIONS = {"target_rel_rms": 3e-3}
N_WINDOWS = 6  # 150 frames of spot (2,930 vertices) in windows of 75,000 frame-vertex values


def wave_poses(vertices: np.ndarray, faces: np.ndarray, frames: int):  # noqa: ANN201 - Poses
    """A smooth travelling wave over ``vertices`` (float32 poses)."""
    from pdeanim.poses import make_poses

    v = np.asarray(vertices, np.float64)
    t = np.linspace(0.0, 1.0, frames)[:, None, None]
    phase = v[None, :, 1:2] * 3.0
    wave = np.concatenate([np.sin(6 * t + phase), 0.5 * np.cos(4 * t + phase), 0 * t + 0 * phase], axis=2)
    return make_poses((v[None] + 0.05 * wave).astype(np.float32), np.asarray(faces, np.int32))


def npz(poses) -> bytes:  # noqa: ANN001
    from pdeanim.poses import poses_to_bytes

    return poses_to_bytes(poses)


def obj(poses) -> bytes:  # noqa: ANN001
    """The OBJ of the poses' first frame (the mesh they are uploaded for)."""
    buf = io.StringIO()
    np.savetxt(buf, poses.vertices[0], fmt="v %.9g %.9g %.9g")
    np.savetxt(buf, poses.faces + 1, fmt="f %d %d %d")
    return buf.getvalue().encode()


@pytest.fixture(scope="module")
def spot_poses(data_dir):  # noqa: ANN001, ANN201
    from pdeanim.mesh.io import load_mesh

    mesh = load_mesh((data_dir / "spot.obj").read_bytes(), filename="spot.obj")
    return wave_poses(mesh.vertices, mesh.faces, 150)


def services_with(backend, tmp_path: Path, workers: int, **env: str) -> Services:  # noqa: ANN001
    """A server and ``workers`` workers with the test's window sizes and the hold hook."""
    hold = tmp_path / "hold"
    hold.mkdir(parents=True, exist_ok=True)
    extra = {**WINDOWS, "PYTHONPATH": f"{HOOK}{os.pathsep}{Path(__file__).resolve().parents[2]}",
             "PDEANIM_TEST_HOLD_DIR": str(hold), "PDEANIM_JOB_SCHED_IDLE": "false", **env}
    svc = Services(backend, tmp_path / "logs", env_extra=extra)
    svc.log_dir.mkdir(parents=True, exist_ok=True)
    try:
        svc.start_server("--workers", "1")  # one HTTP process: starts within the deadline on a loaded machine
        for _ in range(workers):
            svc.start_worker()
    except BaseException:
        svc.stop()  # a server that did not answer in time is not left behind
        raise
    return svc


def submit(api, poses) -> str:  # noqa: ANN001
    mesh = api.post("/v1/meshes", files={"file": ("wave.obj", obj(poses))})
    assert mesh.status_code == 201, mesh.text
    up = api.post(f"/v1/meshes/{mesh.json()['id']}/poses", files={"file": ("wave.npz", npz(poses))})
    assert up.status_code == 201, up.text
    r = api.post("/v1/jobs", json={"kind": "fit", "poses_id": up.json()["id"], "params": OPTIONS})
    assert r.status_code == 202, r.text
    return r.json()["id"]


def tasks(store: Store, job_id: str) -> list[Job]:
    with store.sessions() as session:
        return list(session.scalars(select(Job).where(Job.parent_id == job_id)
                                    .order_by(Job.created_at, Job.window_index)))


def wait_for(condition, what: str, svc: Services, timeout: float = 600):  # noqa: ANN001, ANN201
    """Poll ``condition()`` until it is truthy (a generous deadline: the machine is shared); a timeout
    says what the processes logged."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if got := condition():
            return got
        time.sleep(0.05)
    raise TimeoutError(f"never happened: {what}\n{svc.logs()}")


def running_marker(hold: Path, index: int) -> Path | None:
    return next(iter(hold.glob(f"running-encode-{index}-*")), None)


def in_process_clip(poses):  # noqa: ANN001, ANN201 - ClipParts
    from pdeanim.fit import FitOptions, fit_poses
    from pdeanim.fit.options import FitTolerances

    tol = replace(FitTolerances(), window_fit_values=100_000, window_values=75_000)
    return fit_poses(poses, FitOptions.from_dict(OPTIONS), tolerances=tol)


def test_killed_worker_reruns_its_window_alone(backend, tmp_path, spot_poses):
    """Two workers; the worker encoding window 1 is killed: that task alone runs a second attempt, the clip
    row is written once, and its bytes equal the in-process windowed fit's."""
    hold = tmp_path / "hold"
    svc = services_with(backend, tmp_path, 2)
    store = Store.open(backend.settings())
    try:
        (hold / "hold-encode-1").touch()
        with client(svc, make_key(backend, "alice")) as api:
            job_id = submit(api, spot_poses)
            wait_for(lambda: running_marker(hold, 1), "window 1 encoding", svc)
            task = wait_for(lambda: next((t for t in tasks(store, job_id) if t.phase == "encode"
                                          and t.window_index == 1 and t.state == "running"), None),
                            "the running task of window 1", svc)
            os.kill(int(task.worker_id.rsplit(":", 1)[1]), signal.SIGKILL)
            (hold / "hold-encode-1").unlink()
            job = wait_job(api, job_id, timeout=900)
            assert job["state"] == "succeeded", job
            assert job["result"]["windows"] == N_WINDOWS and job["result"]["windows_done"] == N_WINDOWS
            listed = api.get("/v1/jobs").json()["items"]
            assert [j["id"] for j in listed] == [job_id]  # window tasks are not listed
        rows = tasks(store, job_id)
        assert [r.phase for r in rows].count("encode") == N_WINDOWS and len(rows) == 2 * N_WINDOWS + 2
        assert all(r.state == "succeeded" for r in rows)
        rerun = [(r.phase, r.window_index) for r in rows if r.attempt > 1]
        assert rerun == [("encode", 1)], rerun
        with store.sessions() as session:
            clips = session.scalars(select(ClipRecord).where(ClipRecord.job_id == job_id)).all()
            assert len(clips) == 1 and clips[0].id == job["result"]["clip_id"]
            assert session.scalar(select(func.count()).select_from(ClipRecord)) == 1
        expected = in_process_clip(spot_poses)
        assert store.blobs.get(clips[0].topology_key) == expected.topology
        assert store.blobs.get(clips[0].coefficients_key) == expected.coefficients
        assert not store.blobs.exists(f"windowed/{job_id}/frames.f32")  # intermediates removed
    finally:
        store.close()
        svc.stop()


def test_cancel_and_progress_of_a_windowed_job(backend, tmp_path, spot_poses):
    """One worker, window 2's encoding held: the job is running and its progress counts windows (every
    window summed, two encoded); cancelling it ends every window task and writes no clip."""
    hold = tmp_path / "hold"
    svc = services_with(backend, tmp_path, 1)
    store = Store.open(backend.settings())
    try:
        (hold / "hold-encode-2").touch()
        with client(svc, make_key(backend, "alice")) as api:
            job_id = submit(api, spot_poses)
            wait_for(lambda: running_marker(hold, 2), "window 2 encoding", svc)
            job = api.get(f"/v1/jobs/{job_id}").json()
            assert job["state"] == "running" and job["result"]["windows"] == N_WINDOWS
            assert job["result"]["windows_done"] == 2
            done = (N_WINDOWS + 2) / (2 * N_WINDOWS)  # and window 2's encoding by its own progress, if any
            assert windows.PLAN_SHARE + windows.WINDOW_SHARE * done <= job["progress"] < (
                windows.PLAN_SHARE + windows.WINDOW_SHARE * (done + 1 / (2 * N_WINDOWS)))
            assert f"{N_WINDOWS} of {N_WINDOWS} summed, 2 encoded" in job["stage"]
            r = api.post(f"/v1/jobs/{job_id}/cancel")
            assert r.status_code == 200 and r.json()["state"] == "cancelled", r.text
            wait_for(lambda: all(t.state in ("succeeded", "cancelled") for t in tasks(store, job_id)),
                     "every window task ended", svc)
            states = {(t.phase, t.window_index): t.state for t in tasks(store, job_id)}
            assert all(states[("encode", i)] == "cancelled" for i in range(2, N_WINDOWS)), states
            log = svc.log_dir / "worker0.log"
            # the held window is still running: its worker stops it at the next heartbeat
            wait_for(lambda: "cancelled or deleted" in log.read_text(), "the worker stopped the window", svc)
            (hold / "hold-encode-2").unlink()
        with store.sessions() as session:
            assert session.scalar(select(func.count()).select_from(ClipRecord)) == 0
        assert not store.blobs.exists(f"windowed/{job_id}/frames.f32")
    finally:
        store.close()
        svc.stop()


def test_memory_estimate_is_the_largest_tasks(backend, tmp_path):
    """A long input whose in-process fit is over the job memory limit is accepted when its window tasks
    fit; a limit under the largest task's estimate is refused (413) with the figures."""
    import trimesh

    from pdeanim.fit.budget import fit_memory_bytes, window_task_memory_bytes
    from pdeanim.fit.options import FitTolerances

    sphere = trimesh.creation.icosphere(subdivisions=3)  # 642 vertices
    poses = wave_poses(sphere.vertices, sphere.faces, 2000)
    tol = replace(FitTolerances(), window_fit_values=100_000, window_values=75_000)
    task, whole = window_task_memory_bytes(2000, 642, tol), fit_memory_bytes(2000, 642, tol)
    assert task < whole
    middle = (task + whole) // 2
    cases = [(middle, "true", 202), (middle, "false", 413), (task - 2**20, "true", 413)]
    for i, (limit, tasks_on, status) in enumerate(cases):
        svc = services_with(backend, tmp_path / str(i), 0, PDEANIM_JOB_MEMORY_BYTES=str(limit),
                            PDEANIM_FIT_WINDOW_TASKS=tasks_on)
        try:
            with client(svc, make_key(backend, f"t{i}")) as api:
                mesh = api.post("/v1/meshes", files={"file": ("s.obj", obj(poses))}).json()
                up = api.post(f"/v1/meshes/{mesh['id']}/poses", files={"file": ("s.npz", npz(poses))})
                assert up.status_code == 201, up.text
                r = api.post("/v1/jobs", json={"kind": "fit", "poses_id": up.json()["id"], "params": OPTIONS})
                assert r.status_code == status, (limit, tasks_on, r.text)
                if status == 413:
                    message = r.json()["error"]["message"]
                    assert "2000 frames x 642 vertices" in message and "GiB" in message, message
                    assert ("largest window task" in message) == (tasks_on == "true"), message
        finally:
            svc.stop()
