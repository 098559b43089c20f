"""The worker loop: reap expired leases, claim a job, run the attempt in a child, write the outcome.

SIGTERM/SIGINT: stop claiming; let the running attempt finish for up to ``shutdown_grace_seconds``, then
stop it and give the job back to the queue (no failure counted), and return 0.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import threading
import time

from pdeanim.records import library_versions
from pdeanim_service.settings import Settings
from pdeanim_service.store import windows
from pdeanim_service.store.blobrefs import BlobGone, sweep
from pdeanim_service.store.context import Store
from pdeanim_service.store.models import ClipRecord, Mesh, PosesRecord
from pdeanim_service.store.queue import Claimed
from pdeanim_service.store.scratch import clean_stale, prefix, remove

from .attempt import run_attempt
from .child import Outcome, child_context
from .results import result_writer

log = logging.getLogger("pdeanim.worker")


class Worker:
    """One worker process: claims and runs jobs one at a time until stopped."""

    def __init__(self, settings: Settings, store: Store | None = None):
        self.settings = settings
        self.store = store or Store.open(settings)
        self.id = f"{socket.gethostname()}:{os.getpid()}"
        self.stop_requested = threading.Event()
        self.stop_at: float | None = None
        self.versions = library_versions()
        self.ctx = child_context()
        self.jobs_done = 0
        self.next_sweep = time.monotonic() + settings.blob_sweep_seconds

    def request_stop(self, *_: object) -> None:
        """Signal handler: stop after the current attempt (or abandon it after the grace period)."""
        if not self.stop_requested.is_set():
            self.stop_at = time.monotonic() + self.settings.shutdown_grace_seconds
            self.stop_requested.set()

    def install_signals(self) -> None:
        """Route SIGTERM and SIGINT to :meth:`request_stop`."""
        signal.signal(signal.SIGTERM, self.request_stop)
        signal.signal(signal.SIGINT, self.request_stop)

    def run(self, max_jobs: int | None = None, exit_when_idle: bool = False) -> int:
        """Loop until stopped (or ``max_jobs`` handled / queue empty when asked); returns the exit code."""
        log.info("worker %s started", self.id)
        clean_stale(self.settings.tmp_dir())
        errors = 0
        while not self.stop_requested.is_set():
            try:
                self._reap()
                self._sweep()
                job = self.store.queue.claim(self.id, self.versions)
                errors = 0
            except Exception:  # noqa: BLE001 - database not reachable or not migrated yet: wait and retry
                errors += 1
                log.warning("cannot claim jobs (try %d); retrying", errors, exc_info=errors == 1)
                self.stop_requested.wait(min(self.settings.poll_seconds * 2 ** min(errors, 6), 10.0))
                continue
            if job is None:
                if exit_when_idle:
                    break
                self.stop_requested.wait(self.settings.poll_seconds)
                continue
            try:
                self.handle(job)
            except Exception:  # noqa: BLE001 - the lease expires and another worker retries the job
                log.exception("job %s attempt %d could not be recorded", job.id, job.attempt)
            self.jobs_done += 1
            if max_jobs is not None and self.jobs_done >= max_jobs:
                break
        log.info("worker %s stopped after %d jobs", self.id, self.jobs_done)
        return 0

    def _reap(self) -> None:
        try:
            if n := self.store.queue.reap():
                log.warning("returned %d jobs with expired leases to the queue", n)
        except Exception:  # noqa: BLE001 - the next loop tries again
            log.warning("reaper failed", exc_info=True)

    def _sweep(self) -> None:
        """Remove unreferenced blobs when a sweep is due (PDEANIM_BLOB_SWEEP_SECONDS; 0: never)."""
        if not self.settings.blob_sweep_seconds or time.monotonic() < self.next_sweep:
            return
        self.next_sweep = time.monotonic() + self.settings.blob_sweep_seconds
        try:
            sweep(self.store, self.settings.blob_sweep_grace_seconds)
        except Exception:  # noqa: BLE001 - the next sweep tries again
            log.warning("blob sweep failed", exc_info=True)

    def _payload(self, job: Claimed) -> dict:
        payload = {"id": job.id, "kind": job.kind, "attempt": job.attempt, "params": job.params}
        with self.store.sessions() as session:
            if job.mesh_id:
                mesh = session.get(Mesh, job.mesh_id)
                payload["mesh"] = {"blob_key": mesh.blob_key, "filename": mesh.filename}
            if job.poses_id:
                poses = session.get(PosesRecord, job.poses_id)
                payload["poses"] = {"blob_key": poses.blob_key, "n_frames": poses.n_frames,
                                    "n_vertices": poses.n_vertices,  # to check the fit's memory first
                                    "animation": (poses.meta or {}).get("animation")}  # read from a glTF
            clip_id = (job.params or {}).get("clip_id")
            if clip_id:
                clip = session.get(ClipRecord, clip_id)
                payload["clip"] = {"topology_key": clip.topology_key,
                                   "coefficients_key": clip.coefficients_key}
        return payload

    def _should_stop(self) -> bool:
        return self.stop_at is not None and time.monotonic() > self.stop_at

    def handle(self, job: Claimed) -> Outcome:
        """Run one claimed attempt and record its outcome (fenced)."""
        log.info("job %s (%s) attempt %d", job.id, job.kind, job.attempt)
        started = time.monotonic()
        # the parent owns the attempt's work directory, so it is removed however the child ends
        workdir = self.settings.tmp_dir() / f"{prefix('work')}{job.id}-{job.attempt}"
        try:
            payload = {**self._payload(job), "workdir": str(workdir)}
            outcome = run_attempt(self.ctx, self.store.queue, job, payload,
                                  self.settings.model_dump_json(), self._should_stop,
                                  self.settings.job_timeout_seconds,
                                  lambda part: self.store.queue.store_partial(
                                      job.id, job.attempt, result_writer(job, part, self.store.blobs)))
        finally:
            remove(workdir)
        self._record(job, outcome)
        log.info("job %s attempt %d: %s %s (%.2fs)", job.id, job.attempt, outcome.status, outcome.code,
                 time.monotonic() - started)
        return outcome

    def _record(self, job: Claimed, outcome: Outcome) -> None:
        queue = self.store.queue
        if outcome.status == "done" and (job.parent_id or "windowed" in (outcome.result or {})):
            self._record_window(job, outcome.result or {})
        elif outcome.status == "done":
            try:
                if not queue.finish(job.id, job.attempt, result_writer(job, outcome.result or {},
                                                                        self.store.blobs)):
                    log.warning("job %s attempt %d was fenced out; its result is discarded", job.id,
                                job.attempt)
            except BlobGone as exc:  # a delete took a shared blob of the result meanwhile: run it again
                queue.fail(job.id, job.attempt, str(exc), "blob_lost", retry=True)
        elif outcome.status == "error" and job.parent_id:
            state = queue.fail(job.id, job.attempt, outcome.message, outcome.code, outcome.retry)
            if state == "failed":
                windows.release_blobs(self.store.blobs, job.parent_id, int(job.params["windows"]))
        elif outcome.status == "error" and outcome.partial:
            kept = {k: v for k, v in outcome.partial.items() if k != "next_stage"}
            step = outcome.partial.get("next_stage", "next stage")
            message = f"{step} failed (the results before it are kept: {sorted(kept)}): {outcome.message}"
            queue.fail(
                job.id, job.attempt, message, outcome.code, outcome.retry, {**kept, "failed_stage": step}
            )
        elif outcome.status == "error":
            queue.fail(job.id, job.attempt, outcome.message, outcome.code, outcome.retry)
        elif outcome.status == "stopped":
            queue.release(job.id, job.attempt)
        elif outcome.status == "lost" and self._state(job.id) in ("cancelled", None):
            log.info("job %s was cancelled or deleted; attempt %d stopped", job.id, job.attempt)

    def _record_window(self, job: Claimed, result: dict) -> None:
        """A fit planned in windows enqueues its window tasks; a window task's success advances its fit job
        (the join's writes the clip), and the intermediates go once the fit job succeeded."""
        if job.parent_id is None:
            n_windows = int(result["windowed"]["windows"])
            if not windows.split(self.store.queue, job, n_windows):
                log.warning("job %s attempt %d was fenced out; its plan is discarded", job.id, job.attempt)
                if self._state(job.id) in ("cancelled", None):  # no newer attempt will use the plan
                    windows.release_blobs(self.store.blobs, job.id, n_windows)
            return
        try:
            state = windows.task_done(self.store.queue, job, result, self.store.blobs)
        except BlobGone as exc:  # a delete took a shared blob of the clip meanwhile: run the join again
            self.store.queue.fail(job.id, job.attempt, str(exc), "blob_lost", retry=True)
            return
        if state is None:
            log.warning("window task %s attempt %d was fenced out (or its fit job ended); its result is "
                        "discarded", job.id, job.attempt)
        elif state == "succeeded":
            windows.release_blobs(self.store.blobs, job.parent_id, int(job.params["windows"]))

    def _state(self, job_id: str) -> str | None:
        """The job's state now (None once its row is deleted)."""
        from pdeanim_service.store.models import Job

        with self.store.sessions() as session:
            job = session.get(Job, job_id)
            return None if job is None else job.state


def main(settings: Settings | None = None) -> int:
    """Run a worker on the environment's settings until SIGTERM."""
    worker = Worker(settings or Settings())
    worker.install_signals()
    try:
        return worker.run()
    finally:
        worker.store.close()
