"""Scale-out behaviour of simulate jobs: workers with separate data directories on one database and blob
store simulate on the same (shared) tets, and a simulate + fit whose fit fails keeps its poses."""

from __future__ import annotations

import io
import multiprocessing
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from pdeanim.errors import ParameterError
from pdeanim_service.jobspec import normalize_request
from pdeanim_service.settings import Settings
from pdeanim_service.store.context import Store
from pdeanim_service.store.models import Job, Mesh, PosesRecord
from pdeanim_service.store.tenants import create_key
from pdeanim_worker.loop import Worker
from pdeanim_worker.tetcache import tet_blob_key

SCENE = {"frames": 4, "target_tets": 300}


def _machine(backend, shared: Settings, data_dir: Path, **overrides) -> Settings:
    """Settings of one machine: its own data directory, the shared database and blob store."""
    return backend.settings(
        data_dir=data_dir,
        database_url=shared.resolved_database_url(),
        blob_url=shared.resolved_blob_url(),
        lease_seconds=10,
        backoff_seconds=0.0,
        **overrides,
    )


@pytest.fixture
def shared(backend, tmp_path):
    """The shared store, migrated, with a tenant and the fish mesh uploaded."""
    settings = _machine(backend, backend.settings(), tmp_path / "db-host")
    store = Store.open(settings, run_migrations=True)
    with store.sessions() as s:
        _, tenant = create_key(s, "scaleout")
        data = (Path(__file__).parents[1] / "data" / "fish_capsule.obj").read_bytes()
        s.add(Mesh(id="mesh_fish", tenant_id=tenant.id, filename="fish.obj", blob_key=store.blobs.put(data),
                   n_vertices=0, n_faces=0, stats={}))
        s.commit()
        store.tenant_id = tenant.id
    yield store
    store.close()


def _submit(store: Store, then_fit: bool = False) -> str:
    spec = normalize_request("simulate", SCENE, then_fit, {"segments": 1} if then_fit else None)
    with store.sessions() as s:
        job = store.queue.enqueue(
            s, tenant_id=store.tenant_id, kind="simulate", params=spec, mesh_id="mesh_fish"
        )
        s.commit()
        return job.id


def _run_one(settings: Settings, ctx=None) -> None:  # noqa: ANN001
    worker = Worker(settings)
    if ctx is not None:
        worker.ctx = ctx
    try:
        assert worker.run(max_jobs=1, exit_when_idle=True) == 0 and worker.jobs_done == 1
    finally:
        worker.store.close()


def _poses(store: Store, job: Job) -> np.ndarray:
    with store.sessions() as s:
        row = s.get(PosesRecord, job.result["poses_id"])
    return np.load(io.BytesIO(store.blobs.get(row.blob_key)))["vertices"]


def test_two_workers_on_two_machines_give_bit_identical_poses(backend, shared, tmp_path):
    jobs = [_submit(shared), _submit(shared)]
    spawn = multiprocessing.get_context("spawn")  # sees this test's environment (S3 credentials)
    machines = [_machine(backend, shared.settings, tmp_path / f"machine-{m}") for m in "ab"]
    with ThreadPoolExecutor(2) as pool:  # at the same time: both may tetrahedralize, the first upload wins
        list(pool.map(lambda settings: _run_one(settings, spawn), machines))
    with shared.sessions() as s:
        a, b = (s.get(Job, j) for j in jobs)
    assert a.state == b.state == "succeeded", (a.error, b.error)
    key = a.result["tet_cache_key"]
    assert key and b.result["tet_cache_key"] == key and shared.blobs.exists(tet_blob_key(key))
    pa, pb = _poses(shared, a), _poses(shared, b)
    assert pa.shape == (4, pa.shape[1], 3) and pa.dtype == np.float32
    assert np.array_equal(pa, pb) and pa.tobytes() == pb.tobytes()
    assert not list((tmp_path / "machine-b" / "tmp").iterdir())  # the attempt's work directory is gone


def test_a_failing_fit_keeps_the_simulated_poses(backend, shared, tmp_path, monkeypatch):
    import pdeanim_worker.stages

    def bad_fit(*_, **__):
        raise ParameterError("injected: this fit option cannot fit these poses")

    # fault injection, inherited by the forked child
    monkeypatch.setattr(pdeanim_worker.stages, "_fit", bad_fit)
    job_id = _submit(shared, then_fit=True)
    _run_one(_machine(backend, shared.settings, tmp_path / "machine-c"), multiprocessing.get_context("fork"))
    with shared.sessions() as s:
        job = s.get(Job, job_id)
        rows = s.query(PosesRecord).filter(PosesRecord.job_id == job_id).all()
    assert job.state == "failed" and job.attempt == 1 and job.error_code == "invalid_parameter", job.error
    assert "fit failed" in job.error and "injected" in job.error
    assert job.result["failed_stage"] == "fit" and job.result["tet_cache_key"]
    assert [r.id for r in rows] == [job.result["poses_id"]] and "clip_id" not in job.result
    assert _poses(shared, job).shape == (4, rows[0].n_vertices, 3)
