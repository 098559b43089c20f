"""Store-level tests: migrations, the queue's claim/fence/lease/reaper semantics, and the blob stores."""

from __future__ import annotations

import threading
import time

import pytest
from sqlalchemy import select

from pdeanim_service.store.blobs import BlobNotFound, LocalBlobStore
from pdeanim_service.store.context import Store
from pdeanim_service.store.models import Job, Mesh
from pdeanim_service.store.tenants import create_key, tenant_for_key


@pytest.fixture
def store(backend):
    st = Store.open(
        backend.settings(lease_seconds=0.5, backoff_seconds=0.0, max_attempts=2), run_migrations=True
    )
    yield st
    st.close()


@pytest.fixture
def tenant(store) -> str:
    with store.sessions() as s:
        key, t = create_key(s, "acme")
        s.commit()
        assert tenant_for_key(s, key) == t.id
        assert tenant_for_key(s, key + "x") is None
        mesh = Mesh(
            id="mesh_1", tenant_id=t.id, filename="a.obj", blob_key="k", n_vertices=3, n_faces=1, stats={}
        )
        s.add(mesh)
        s.commit()
        return t.id


def _enqueue(store, tenant, n=1) -> list[str]:
    with store.sessions() as s:
        jobs = [store.queue.enqueue(s, tenant_id=tenant, kind="fit", params={"i": i}, mesh_id="mesh_1")
                for i in range(n)]
        s.commit()
        return [j.id for j in jobs]


def test_migrations_are_idempotent(backend, store):
    from pdeanim_service.store.db import migrate

    migrate(backend.settings().resolved_database_url())
    assert store.check() == {"database": "ok", "blobs": "ok"}


def test_claim_fence_and_finish(store, tenant):
    (job_id,) = _enqueue(store, tenant)
    claimed = store.queue.claim("w1", {"pdeanim": "x"})
    assert claimed.id == job_id and claimed.attempt == 1 and claimed.params == {"i": 0}
    assert store.queue.claim("w2") is None
    assert store.queue.report(job_id, 1, 0.4, "simulate 40/100")
    assert not store.queue.report(job_id, 2, 0.5, "stale attempt")
    assert not store.queue.finish(job_id, 2, lambda s: {"clip_id": "no"})
    assert store.queue.finish(job_id, 1, lambda s: {"clip_id": "c"})
    assert not store.queue.finish(job_id, 1, lambda s: {"clip_id": "twice"})
    with store.sessions() as s:
        job = s.get(Job, job_id)
        assert (job.state, job.result, job.progress, job.versions) == ("succeeded", {"clip_id": "c"}, 1.0,
                                                                       {"pdeanim": "x"})


def _reap_when_expired(store: Store, deadline_s: float = 60.0) -> int:
    """Call the reaper until it returns a job (the lease ran out), within a generous deadline."""
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        if n := store.queue.reap():
            return n
        time.sleep(0.1)
    raise TimeoutError("no lease expired")


def test_expired_lease_is_reaped_and_old_attempt_fenced_out(backend, tenant):
    # a 3 s lease: long enough that the first reap sees it alive even on a stalled machine, short for the test
    store = Store.open(backend.settings(lease_seconds=3.0, backoff_seconds=0.0, max_attempts=2),
                       run_migrations=True)
    try:
        (job_id,) = _enqueue(store, tenant)
        first = store.queue.claim("w1")
        assert store.queue.reap() == 0
        assert _reap_when_expired(store) == 1
        assert not store.queue.heartbeat(job_id, first.attempt)
        second = store.queue.claim("w2")
        assert second.attempt == 2
        assert not store.queue.finish(job_id, 1, lambda s: {"from": "w1"})
        assert _reap_when_expired(store) == 1  # second loss: max_attempts=2 -> failed
        with store.sessions() as s:
            job = s.get(Job, job_id)
            assert job.state == "failed" and "lease expired" in job.error and job.failures == 2
    finally:
        store.close()


def test_fail_retries_then_gives_up_and_input_errors_do_not_retry(store, tenant):
    a, b = _enqueue(store, tenant, 2)
    ca = store.queue.claim("w")
    assert store.queue.fail(ca.id, ca.attempt, "boom", "RuntimeError", retry=True) == "queued"
    cb = store.queue.claim("w")
    assert store.queue.fail(cb.id, cb.attempt, "bad mesh", "invalid_mesh", retry=False) == "failed"
    ca2 = store.queue.claim("w")
    assert (ca2.id, ca2.attempt) == (a, 2)
    assert store.queue.fail(ca2.id, ca2.attempt, "boom", "RuntimeError", retry=True) == "failed"
    assert store.queue.release(ca2.id, ca2.attempt) is False


def test_release_requeues_without_counting_a_failure(store, tenant):
    (job_id,) = _enqueue(store, tenant)
    c = store.queue.claim("w")
    assert store.queue.release(job_id, c.attempt)
    c2 = store.queue.claim("w")
    assert c2.attempt == 2
    with store.sessions() as s:
        assert s.get(Job, job_id).failures == 0


def test_concurrent_claims_hand_out_each_job_once(store, tenant):
    ids = _enqueue(store, tenant, 30)
    got: list[str] = []
    lock = threading.Lock()

    def drain(name: str) -> None:
        while (c := store.queue.claim(name)) is not None:
            with lock:
                got.append(c.id)

    threads = [threading.Thread(target=drain, args=(f"w{i}",)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(got) == sorted(ids)
    with store.sessions() as s:
        assert all(j.attempt == 1 for j in s.execute(select(Job)).scalars())


def test_blob_store_roundtrip(store, tmp_path):
    blobs = store.blobs
    key = blobs.put(b"hello")
    assert blobs.put(b"hello") == key and blobs.get(key) == b"hello" and blobs.exists(key)
    f = tmp_path / "f.bin"
    f.write_bytes(b"x" * 3_000_000)
    fkey = blobs.put_file(f)
    assert blobs.get(fkey) == b"x" * 3_000_000
    blobs.delete(key)
    assert not blobs.exists(key)
    with pytest.raises(BlobNotFound):
        blobs.get(key)
    with pytest.raises(ValueError):
        blobs.get("../etc/passwd")


def test_local_blob_store_leaves_no_temp_files(tmp_path):
    blobs = LocalBlobStore(tmp_path / "b")
    blobs.put(b"abc")
    assert [p.name for p in (tmp_path / "b").rglob("*") if p.name.startswith(".tmp")] == []


def test_fenced_out_finish_writes_no_result_rows(store, tenant):
    from pdeanim_service.store.models import ClipRecord

    (job_id,) = _enqueue(store, tenant)
    store.queue.claim("w1")

    def write(session):
        session.add(ClipRecord(id="clip_x", tenant_id=tenant, mesh_id="mesh_1", job_id=job_id, kind="k",
                               topology_key="t", coefficients_key="c", topology_id="t", report={}))
        return {"clip_id": "clip_x"}

    assert not store.queue.finish(job_id, 7, write)
    with store.sessions() as s:
        assert s.get(ClipRecord, "clip_x") is None and s.get(Job, job_id).state == "running"
    assert store.queue.finish(job_id, 1, write)
    with store.sessions() as s:
        assert s.get(ClipRecord, "clip_x").job_id == job_id and s.get(Job, job_id).result == {
            "clip_id": "clip_x"
        }


def test_put_if_absent_first_writer_wins(store):
    """Racing writers of one key: exactly one stores, every reader then sees that writer's bytes."""
    blobs, key = store.blobs, "tets-race"
    won: list[bytes] = []
    lock = threading.Lock()

    def write(i: int) -> None:
        data = f"writer {i}".encode() * 1000
        if blobs.put_if_absent(data, key):
            with lock:
                won.append(data)

    threads = [threading.Thread(target=write, args=(i,)) for i in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(won) == 1 and blobs.get(key) == won[0]
    assert not blobs.put_if_absent(b"late", key) and blobs.get(key) == won[0]
