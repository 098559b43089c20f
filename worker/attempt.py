"""The parent side of one attempt: start the child, relay its progress to the job row, renew the lease,
and stop it when the lease is lost, the worker is told to stop, or it runs past the timeout."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from pdeanim_service.store.queue import Claimed, JobQueue
from pdeanim_service.store.windows import task_progress

from .child import Outcome, child_main

log = logging.getLogger("pdeanim.worker")
PROGRESS_WRITE_SECONDS = 0.5


class Heartbeat(threading.Thread):
    """Renews the attempt's lease every lease/3 seconds; sets ``lost`` when the attempt no longer owns it."""

    def __init__(self, queue: JobQueue, job: Claimed):
        super().__init__(daemon=True, name=f"heartbeat-{job.id}")
        self.queue, self.job = queue, job
        self.lost, self.done = threading.Event(), threading.Event()

    def run(self) -> None:
        """Beat until done or lost."""
        interval = max(self.queue.policy.lease_seconds / 3.0, 0.05)
        while not self.done.wait(interval):
            try:
                if not self.queue.heartbeat(self.job.id, self.job.attempt):
                    self.lost.set()
                    return
            except Exception:  # noqa: BLE001 - a database hiccup: try again next beat
                log.warning("heartbeat of %s failed", self.job.id, exc_info=True)


# stores a partial result (fenced); its ids, or None if fenced out
PartialWriter = Callable[[dict], "dict | None"]


def run_attempt(ctx, queue: JobQueue, job: Claimed, payload: dict, settings_json: str,  # noqa: ANN001
                should_stop: Callable[[], bool], timeout: float,
                on_partial: PartialWriter | None = None) -> Outcome:
    """Run one attempt in a child process and wait for its outcome (partial results go to ``on_partial``)."""
    import os

    beat = Heartbeat(queue, job)
    beat.start()  # before the child: its start may also start the forkserver, which preloads numpy, scipy and
    # trimesh and can outlast a lease on a loaded machine (the job was then reaped while it was starting)
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=child_main, args=(child, payload, settings_json, os.getpid()), daemon=True)
    try:
        proc.start()
        child.close()
        stored: dict = {}
        outcome = _pump(proc, parent, queue, job, beat, should_stop, time.monotonic() + timeout,
                        _partial_sink(on_partial, stored, beat))
        outcome.partial = stored or None
        if outcome.status in ("done", "error"):
            proc.join(5)  # the child removes its work directory and exits right after its last message
        return outcome
    finally:
        beat.done.set()
        child.close()
        if proc.pid is not None:  # it started
            if proc.is_alive():
                proc.kill()
            proc.join(5)
        parent.close()


def _partial_sink(on_partial: PartialWriter | None, stored: dict, beat: Heartbeat) -> Callable[[dict], None]:
    """Store one partial result through ``on_partial`` and remember its ids (with the stage that follows)."""

    def sink(part: dict) -> None:
        if on_partial is None:
            return
        ids = on_partial(part)
        if ids is None:
            beat.lost.set()  # fenced out: a newer attempt owns the job
            return
        stored.update(ids)
        stored["next_stage"] = str(part.get("next_stage", "next stage"))

    return sink


def _pump(proc, conn, queue: JobQueue, job: Claimed, beat: Heartbeat,  # noqa: ANN001
          should_stop: Callable[[], bool], deadline: float, partial: Callable[[dict], None]) -> Outcome:
    pending, last_write = None, 0.0
    while True:
        if beat.lost.is_set():
            return Outcome("lost", message="the lease was lost (another worker owns the job now)")
        if should_stop():
            return Outcome("stopped")
        if time.monotonic() > deadline:
            return Outcome(
                "error", code="timeout", message="the attempt ran past PDEANIM_JOB_TIMEOUT_SECONDS"
            )
        try:
            ready = conn.poll(0.1)
            msg = conn.recv() if ready else None
        except (EOFError, OSError):
            proc.join(5)
            return Outcome("error", code="crashed", message=f"the job process died (exit code "
                                                            f"{proc.exitcode})")
        if msg is not None and msg[0] == "progress":
            pending = msg[1:]
        elif msg is not None and msg[0] == "partial":
            partial(msg[1])
        elif msg is not None and msg[0] == "done":
            return Outcome("done", result=msg[1])
        elif msg is not None and msg[0] == "error":
            return Outcome("error", code=msg[1], message=msg[2], retry=bool(msg[3]))
        if pending and time.monotonic() - last_write >= PROGRESS_WRITE_SECONDS:
            if not queue.report(job.id, job.attempt, *pending):
                beat.lost.set()
            elif job.parent_id:  # a window task: its fit job's progress follows it
                task_progress(queue, job)
            pending, last_write = None, time.monotonic()
