"""The helper-thread job pool: every job runs exactly once, errors reach the caller, rounds do not mix."""

from __future__ import annotations

import threading

import pytest

from pdeanim.sim.workers import JobPool


def test_every_job_runs_once_over_many_rounds():
    pool = JobPool(2)
    assert pool.size == 3
    for n in (0, 1, 2, 7, 30):
        counts = [0] * n
        lock = threading.Lock()

        def job(i: int, counts: list[int] = counts, lock: threading.Lock = lock) -> None:
            with lock:
                counts[i] += 1

        pool.run([lambda i=i: job(i) for i in range(n)])
        assert counts == [1] * n


def test_run_waits_for_jobs_started_by_helpers():
    pool = JobPool(1)
    release, started, done = threading.Event(), threading.Event(), []

    def slow() -> None:
        started.set()
        assert release.wait(120)  # generous: the machine may be loaded
        done.append("slow")

    def fast() -> None:
        assert started.wait(120)  # the helper holds the other job: this thread must not return before it ends
        release.set()
        done.append("fast")

    pool.run([slow, fast])
    assert sorted(done) == ["fast", "slow"]


def test_job_errors_reach_the_caller():
    pool = JobPool(1)

    def bad() -> None:
        raise ValueError("boom")

    with pytest.raises(ValueError, match="boom"):
        pool.run([bad, lambda: None])
    pool.run([lambda: None])  # still usable


def test_concurrent_callers_each_get_all_their_jobs_run():
    pool = JobPool(1)
    results: dict[int, list[int]] = {0: [], 1: [], 2: []}

    def caller(k: int) -> None:
        for _ in range(50):
            out: list[int] = []
            pool.run([lambda i=i, out=out: out.append(i) for i in range(4)])
            results[k].append(sorted(out) == [0, 1, 2, 3])

    threads = [threading.Thread(target=caller, args=(k,)) for k in results]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(len(r) == 50 and all(r) for r in results.values())
