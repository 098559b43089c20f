"""One attempt's lease: it is renewed from the moment the attempt begins, also while the child process is
still
starting (the first start also starts the forkserver, which can outlast a lease on a loaded machine)."""

from __future__ import annotations

import multiprocessing
import threading
import time

from pdeanim_service.store.context import Store
from pdeanim_service.store.models import Mesh
from pdeanim_service.store.tenants import create_key
from pdeanim_worker.attempt import run_attempt

LEASE = 3.0


class SlowStart:
    """Fault injection: a multiprocessing context whose processes take ``delay`` seconds to start."""

    def __init__(self, delay: float) -> None:
        self.ctx, self.delay = multiprocessing.get_context("fork"), delay

    def Pipe(self, duplex: bool = True):  # noqa: ANN201, N802 - the multiprocessing API
        return self.ctx.Pipe(duplex=duplex)

    def Process(self, *args, **kwargs):  # noqa: ANN002, ANN003, ANN201, N802
        proc = self.ctx.Process(*args, **kwargs)
        start = proc.start

        def slow_start() -> None:
            time.sleep(self.delay)
            start()

        proc.start = slow_start
        return proc


def test_lease_is_renewed_while_the_child_starts(backend):
    settings = backend.settings(lease_seconds=LEASE, backoff_seconds=0.0)
    store = Store.open(settings, run_migrations=True)
    try:
        with store.sessions() as s:
            _, tenant = create_key(s, "attempt")
            s.add(Mesh(id="mesh_a", tenant_id=tenant.id, filename="a.obj", blob_key="k", n_vertices=3,
                       n_faces=1, stats={}))
            s.commit()
            job = store.queue.enqueue(s, tenant_id=tenant.id, kind="fit", params={}, mesh_id="mesh_a")
            s.commit()
            job_id = job.id
        claimed = store.queue.claim("w1")
        reaped: list[int] = []
        reaper = threading.Timer(
            3 * LEASE, lambda: reaped.append(store.queue.reap())
        )  # another worker's reaper
        reaper.start()
        payload = {
            "id": job_id,
            "kind": "fit",
            "params": {},
        }  # no poses: the child fails at once, after its start
        outcome = run_attempt(
            SlowStart(4 * LEASE),
            store.queue,
            claimed,
            payload,
            settings.model_dump_json(),
            lambda: False,
            timeout=600,
        )
        reaper.join()
        assert reaped == [0], "the job was reaped while its child process was starting"
        assert outcome.status == "error", outcome
        assert (
            store.queue.fail(job_id, claimed.attempt, outcome.message, outcome.code, retry=False) == "failed"
        )
    finally:
        store.close()


def test_a_deterministic_error_fails_the_attempt_without_retry(backend):
    """A stage raising a computation error (here KeyError: a fit payload without poses) in a real child
    process ends the attempt as ``computation_error``, not retried, naming the error and where it arose."""
    settings = backend.settings(lease_seconds=LEASE, backoff_seconds=0.0)
    store = Store.open(settings, run_migrations=True)
    try:
        with store.sessions() as s:
            _, tenant = create_key(s, "attempt-error")
            job = store.queue.enqueue(s, tenant_id=tenant.id, kind="fit", params={})
            s.commit()
        claimed = store.queue.claim("w1")
        payload = {"id": job.id, "kind": "fit", "params": {"params": {}}}
        outcome = run_attempt(multiprocessing.get_context("fork"), store.queue, claimed, payload,
                              settings.model_dump_json(), lambda: False, timeout=600)
        assert (outcome.status, outcome.code, outcome.retry) == ("error", "computation_error", False), outcome
        assert outcome.message.startswith("the fit job failed with KeyError: 'poses' at worker/stages.py:")
        assert "not retried" in outcome.message
    finally:
        store.close()
