"""A tiny pool of helper threads that share a list of independent jobs with the calling thread.

Made for GIL-free numba kernels on shared cores: jobs are claimed one at a time, the calling thread works too,
and it waits only for jobs a helper has actually started. A helper that the OS has not scheduled yet never
holds the caller up (an OpenMP region would wait for it at its barrier; measured 3-10x slower than one thread
on a busy 2-core machine). Which thread runs a job does not change what the job computes.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence


class JobPool:
    """``n_helpers`` daemon threads; :meth:`run` executes jobs on them and on the caller, returns when all
    ended."""

    def __init__(self, n_helpers: int) -> None:
        self._lock = threading.Lock()
        self._busy = threading.Lock()
        self._go = threading.Condition(self._lock)
        self._jobs: Sequence[Callable[[], None]] = ()
        self._next = 0
        self._running = 0
        self._round = 0
        self._finished = threading.Event()
        self._errors: list[BaseException] = []
        self._threads = [threading.Thread(target=self._helper, daemon=True, name=f"pdeanim-sim-{i}")
                         for i in range(n_helpers)]
        for t in self._threads:
            t.start()

    @property
    def size(self) -> int:
        """Threads that run jobs, the caller included."""
        return len(self._threads) + 1

    def run(self, jobs: Sequence[Callable[[], None]]) -> None:
        """Run every job exactly once (in any order, on any thread); re-raise the first job error.

        Safe to call from several threads: a call made while another is in progress runs its jobs inline.
        """
        if not self._busy.acquire(blocking=False):
            for job in jobs:
                job()
            return
        try:
            self._run(jobs)
        finally:
            self._busy.release()

    def _run(self, jobs: Sequence[Callable[[], None]]) -> None:
        """One round: publish the jobs, work on them, wait for those the helpers started."""
        with self._lock:
            self._jobs, self._next, self._running, self._errors = jobs, 0, 0, []
            self._finished = finished = threading.Event()
            self._round += 1
            self._go.notify_all()
        self._work()
        with self._lock:
            wait = self._running > 0
        if wait:
            finished.wait()
        if self._errors:
            raise self._errors[0]

    def _work(self) -> None:
        """Claim and run jobs until none is left unclaimed."""
        while True:
            with self._lock:
                if self._next >= len(self._jobs):
                    return
                job, finished = self._jobs[self._next], self._finished
                self._next += 1
                self._running += 1
            try:
                job()
            except BaseException as exc:  # noqa: BLE001 - handed to the caller of run
                self._errors.append(exc)
            with self._lock:
                self._running -= 1
                if self._running == 0 and self._next >= len(self._jobs):
                    finished.set()

    def _helper(self) -> None:
        """Helper thread: wait for a new round of jobs, join in, repeat."""
        seen = 0
        while True:
            with self._lock:
                while self._round == seen:
                    self._go.wait()
                seen = self._round
            self._work()
