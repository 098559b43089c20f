"""Store-level tests of window tasks (pdeanim_service.store.windows): the phases in order, concurrent
finishes that
enqueue the next phase exactly once, a task failing for good failing its fit job, cancel reaching every
task, and ranged blob reads."""

from __future__ import annotations

import threading

import pytest
from sqlalchemy import select

from pdeanim_service.store import windows
from pdeanim_service.store.context import Store
from pdeanim_service.store.models import ClipRecord, Job, Mesh
from pdeanim_service.store.tenants import create_key

W = 3
CLIP = {"kind": "dynamic-pde", "topology_key": "t", "coefficients_key": "c", "topology_id": "x", "report": {}}


@pytest.fixture
def store(backend):
    st = Store.open(backend.settings(lease_seconds=30, backoff_seconds=0.0, max_attempts=2),
                    run_migrations=True)
    yield st
    st.close()


def _enqueued_fit(store) -> str:  # noqa: ANN001 - the store fixture
    """A queued fit job of tenant acme on a mesh of its own: its id."""
    with store.sessions() as s:
        _, t = create_key(s, "acme")
        s.add(Mesh(id="mesh_1", tenant_id=t.id, filename="a.obj", blob_key="k", n_vertices=3, n_faces=1,
                   stats={}))
        s.commit()
        job = store.queue.enqueue(s, tenant_id=t.id, kind="fit", params={}, mesh_id="mesh_1")
        s.commit()
        job_id = job.id
    return job_id


@pytest.fixture
def fit_job(store) -> str:
    """A fit job claimed and split into W gram tasks."""
    job_id = _enqueued_fit(store)
    claimed = store.queue.claim("w0")
    assert claimed.id == job_id and windows.split(store.queue, claimed, W)
    assert not windows.split(store.queue, claimed, W)  # fenced: the job waits already
    return job_id


def _row(store, job_id) -> Job:
    with store.sessions() as s:
        return s.get(Job, job_id)


def _run_phase(store, phase: str, n: int, result: dict | None = None) -> list[str | None]:
    """Claim and finish ``n`` tasks, all of ``phase``; the fit job's state after each."""
    out = []
    for _ in range(n):
        task = store.queue.claim("w1")
        assert task is not None and task.phase == phase and task.kind == windows.TASK_KIND
        out.append(windows.task_done(store.queue, task, result or {"phase": phase}, store.blobs))
    return out


def test_phases_in_order_and_progress_counts_windows(store, fit_job):
    assert _row(store, fit_job).state == "waiting"
    _run_phase(store, "gram", W)
    job = _row(store, fit_job)
    assert job.progress == pytest.approx(windows.PLAN_SHARE + windows.WINDOW_SHARE * W / (2 * W))
    assert f"{W} of {W} summed" in job.stage
    _run_phase(store, "space", 1)
    _run_phase(store, "encode", W - 1)
    assert _row(store, fit_job).result == {"windows": W, "windows_done": W - 1}
    _run_phase(store, "encode", 1)
    store.blobs.put(b"topology", key="t")  # the join's clip row names stored blobs (checked under their lock)
    store.blobs.put(b"coefficients", key="c")
    assert _run_phase(store, "join", 1, {"clip": CLIP}) == ["succeeded"]
    assert store.queue.claim("w1") is None
    job = _row(store, fit_job)
    assert job.state == "succeeded" and job.progress == 1.0 and job.result["windows_done"] == W
    with store.sessions() as s:
        clips = s.scalars(select(ClipRecord).where(ClipRecord.job_id == fit_job)).all()
        assert [c.id for c in clips] == [job.result["clip_id"]]


def test_progress_never_goes_back_from_submission_to_the_clip(store):
    """The fit job's progress as its planning attempt (retried once), its window tasks (one retried) and the
    join report it, recorded at every write: never lower than before, ending at 1.0 with the clip."""
    from pdeanim_worker.windowtasks import READ_SHARE, STORE_AT

    job_id = _enqueued_fit(store)
    seen = [_row(store, job_id).progress]

    def record() -> None:
        seen.append(_row(store, job_id).progress)

    def plan(claimed) -> None:  # noqa: ANN001 - the planning attempt's share (pdeanim_worker.windowtasks.plan_fit)
        for f in (0.0, 0.4, 0.85, 1.0):
            assert store.queue.report(claimed.id, claimed.attempt, windows.PLAN_SHARE * f, "fit: plan")
            record()

    first = store.queue.claim("w0")
    plan(first)
    assert store.queue.fail(first.id, first.attempt, "lost", "RuntimeError", True) == "queued"
    again = store.queue.claim("w0")
    assert again.attempt == 2
    plan(again)  # the retry reports from 0 again
    assert windows.split(store.queue, again, W)
    record()
    for phase, n, steps in (("gram", W, (0.0, 1.0)), ("space", 1, (0.0,)), ("encode", W, (0.0, 0.5, 1.0)),
                            ("join", 1, (0.0, READ_SHARE / 2, READ_SHARE, STORE_AT, 1.0))):
        for i in range(n):
            task = store.queue.claim("w1")
            assert task.phase == phase
            if phase == "encode" and i == 1:  # a window task retried: it starts again at 0
                for f in steps:
                    assert store.queue.report(task.id, task.attempt, f, phase)
                    windows.task_progress(store.queue, task)
                    record()
                assert store.queue.fail(task.id, task.attempt, "lost", "RuntimeError", True) == "queued"
                task = store.queue.claim("w1")
            for f in steps:
                assert store.queue.report(task.id, task.attempt, f, phase)
                windows.task_progress(store.queue, task)
                record()
            if phase == "join":  # the join's clip row names stored blobs (checked under their lock)
                store.blobs.put(b"topology", key="t")
                store.blobs.put(b"coefficients", key="c")
            windows.task_done(store.queue, task, {"clip": CLIP} if phase == "join" else {"phase": phase},
                              store.blobs)
            record()
    assert _row(store, job_id).state == "succeeded"
    assert all(b >= a for a, b in zip(seen, seen[1:], strict=False)), seen
    assert seen[0] == 0.0 and seen[-1] == 1.0
    assert len(set(seen)) > 2 * W + 6, seen  # it moved while the windows and the join ran
    join_steps = [p for p in seen if 1.0 - windows.JOIN_SHARE < p < 1.0]
    assert len(set(join_steps)) >= 3, seen  # the join reported in steps


def test_concurrent_finishes_enqueue_the_next_phase_once(store, fit_job):
    claimed = [store.queue.claim(f"w{i}") for i in range(W)]
    barrier = threading.Barrier(W)

    def finish(task) -> None:
        barrier.wait()
        windows.task_done(store.queue, task, {}, store.blobs)

    threads = [threading.Thread(target=finish, args=(t,)) for t in claimed]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    with store.sessions() as s:
        phases = s.scalars(select(Job.phase).where(Job.parent_id == fit_job, Job.state == "queued")).all()
    assert phases == ["space"]


def test_a_task_failing_for_good_fails_the_fit_and_cancels_the_others(store, fit_job):
    task = store.queue.claim("w1")
    assert store.queue.fail(task.id, task.attempt, "boom", "RuntimeError", True) == "queued"
    claimed = [store.queue.claim("w2") for _ in range(W)]
    (first,) = [t for t in claimed if t.id == task.id]  # the retry of the failed window
    assert first.attempt == 2
    assert store.queue.fail(first.id, first.attempt, "boom again", "RuntimeError", True) == "failed"
    job = _row(store, fit_job)
    assert job.state == "failed" and "boom again" in job.error and job.error_code == "RuntimeError"
    with store.sessions() as s:
        states = {t.id: t.state for t in s.scalars(select(Job).where(Job.parent_id == fit_job))}
    assert states.pop(first.id) == "failed" and set(states.values()) == {"cancelled"}
    second = next(t for t in claimed if t.id != task.id)
    assert windows.task_done(store.queue, second, {}, store.blobs) is None  # fenced out: cancelled


def test_cancel_reaches_every_task(store, fit_job):
    running = store.queue.claim("w1")
    assert store.queue.cancel([fit_job]) == 1
    with store.sessions() as s:
        states = {t.state for t in s.scalars(select(Job).where(Job.parent_id == fit_job))}
    assert states == {"cancelled"} and _row(store, fit_job).state == "cancelled"
    assert not store.queue.heartbeat(running.id, running.attempt)  # its worker stops it
    assert windows.task_done(store.queue, running, {}, store.blobs) is None


def test_ranged_blob_reads(store, tmp_path):
    key = windows.frames_key("job_x")
    store.blobs.put(bytes(range(256)) * 4, key=key)
    assert store.blobs.get_range(key, 250, 10) == bytes([250, 251, 252, 253, 254, 255, 0, 1, 2, 3])
    assert store.blobs.get_range(key, 1020, 10) == bytes([252, 253, 254, 255])  # the end of the blob
    store.blobs.get_file(key, tmp_path / "copy")  # the planning task's copy of the stored poses
    assert (tmp_path / "copy").read_bytes() == bytes(range(256)) * 4
    windows.release_blobs(store.blobs, "job_x", 2)
    assert not store.blobs.exists(key)


def test_streamed_planning_stores_the_plan_and_frames_of_the_in_memory_one(store, tmp_path):
    """The planning task that inflates the stored poses straight into the frames file (no poses in memory)
    stores the very plan and raw frames of the one that loads them."""
    import numpy as np
    import trimesh

    from pdeanim.fit import FitOptions, FitTolerances
    from pdeanim.poses import load_poses_npz, make_poses, poses_to_bytes
    from pdeanim_worker.windowtasks import plan_fit, plan_fit_streamed

    mesh = trimesh.creation.icosphere(subdivisions=2)
    t = np.linspace(0.0, 1.0, 40)[:, None, None]
    x = np.asarray(mesh.vertices)[None] * (1.0 + 0.2 * np.sin(2 * np.pi * t))
    key = store.blobs.put(poses_to_bytes(make_poses(x.astype(np.float32), np.asarray(mesh.faces))))
    tol = FitTolerances(window_fit_values=0, window_values=10 * len(mesh.vertices))
    options = FitOptions(target_rel_rms=3e-3)
    streamed = plan_fit_streamed("job_s", key, None, options, tol, store.blobs, lambda *_: None,
                                 tmp_path / "s")
    loaded = plan_fit("job_m", load_poses_npz(store.blobs.get(key)), options, tol, store.blobs,
                      lambda *_: None, tmp_path / "m")
    assert streamed == loaded and streamed["windowed"]["windows"] == 4
    for of in (windows.frames_key, windows.plan_key):
        assert store.blobs.get(of("job_s")) == store.blobs.get(of("job_m"))
    assert not list((tmp_path / "s").iterdir())  # the copies in the work directory are gone
