"""One job attempt in a child process: memory limit, parent watchdog, progress messages over a pipe.

Messages child -> parent: ``("progress", fraction, stage)``, ``("partial", result_part)`` (a result to store
at once, e.g. simulated poses before their fit), then exactly one of ``("done", result)`` or
``("error", code, message, retry)``. A child that dies without either (crash, kill, OOM) is a failed
attempt that the parent retries; the worker itself keeps running.
"""

from __future__ import annotations

import multiprocessing
import os
import resource
import shutil
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pdeanim.outofmemory import out_of_memory
from pdeanim_service.store.scratch import alive, die_with_parent

PRELOAD = ["numpy", "scipy.sparse", "scipy.linalg", "trimesh", "pdeanim_worker.stages"]


def child_context() -> multiprocessing.context.BaseContext:
    """A forkserver context that preloads the heavy libraries once, so each attempt starts fast and clean."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(PRELOAD)
    return ctx


def _orphaned(parent_pid: int) -> bool:
    """Whether the worker (``parent_pid``) is gone: nobody will take this attempt's result."""
    return os.getppid() == 1 or not alive(parent_pid)


def _watch_parent(parent_pid: int) -> None:
    """Backstop of the parent-death signal (where prctl is unavailable): exit once the worker is gone."""
    while True:
        time.sleep(1.0)
        if _orphaned(parent_pid):
            os._exit(3)


def _warm_blas() -> None:
    import numpy as np

    a = np.ones((256, 256))
    np.dot(a, a)
    np.linalg.solve(a + 256 * np.eye(256), a[0])


CGROUP_V1_CPU = Path("/sys/fs/cgroup/cpu")


def lower_priority(nice: int, cpu_shares: int = 0, cgroup_root: Path = CGROUP_V1_CPU,
                   sched_idle: bool = False) -> str | None:
    """Let the API keep its latency while jobs run: nice this process by ``nice``; with ``sched_idle`` (Linux)
    put it under SCHED_IDLE, so it runs only on CPU time nothing else wants; and with ``cpu_shares`` > 0
    where a cgroup v1 cpu hierarchy is writable (Linux, root), move it into the group ``pdeanim-jobs`` with
    that ``cpu.shares`` (1024 = one ordinary process), so all job children together weigh that much. Called
    before the job starts threads (BLAS, numba), which inherit the calling thread's nice and policy.
    Returns the cgroup joined, or None (cgroup v2 needs a delegated subtree and is not attempted)."""
    if sched_idle and hasattr(os, "SCHED_IDLE"):
        try:
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
        except OSError:  # refused by a sandbox (seccomp): nice alone
            pass
    if nice > 0:
        os.nice(nice)
    if cpu_shares <= 0 or not os.access(cgroup_root / "cgroup.procs", os.W_OK):
        return None
    group = cgroup_root / "pdeanim-jobs"
    try:
        group.mkdir(exist_ok=True)
        (group / "cpu.shares").write_text(str(int(cpu_shares)))
        (group / "cgroup.procs").write_text(str(os.getpid()))
        return str(group)
    except OSError:  # read-only or restricted hierarchy: nice alone
        return None


def child_main(conn, job: dict[str, Any], settings_json: str, parent_pid: int) -> None:  # noqa: ANN001
    """Entry point of the child: run the job's stage, send the outcome on ``conn``, and exit at once. It dies
    with its parent (the worker's forkserver, which exits when the worker does): SIGKILL by the kernel, so
    no job process outlives a killed worker."""
    die_with_parent()
    if _orphaned(parent_pid):  # the worker died before the signal was armed
        os._exit(3)
    threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True).start()
    code = 0
    try:
        _run(conn, job, settings_json)
    except BaseException:  # noqa: BLE001 - even sending failed (broken pipe, no memory): just exit
        code = 4
    finally:
        try:
            conn.close()
        finally:
            os._exit(
                code
            )  # skip interpreter teardown: nothing left to flush, and it can hang under RLIMIT_AS


def _run(conn, job: dict[str, Any], settings_json: str) -> None:  # noqa: ANN001
    from pdeanim.errors import InputError
    from pdeanim_service.settings import Settings
    from pdeanim_service.store.blobs import open_blob_store

    from .stages import STAGES

    settings = Settings.model_validate_json(settings_json)
    lower_priority(settings.job_nice, settings.job_cpu_shares, sched_idle=settings.job_sched_idle)
    memory = settings.job_memory_limit()
    workdir = Path(job["workdir"]) if job.get("workdir") else \
        Path(tempfile.mkdtemp(prefix=f"{job['id']}-", dir=settings.tmp_dir()))
    workdir.mkdir(parents=True, exist_ok=True)
    last = [0.0]

    def progress(fraction: float, stage: str) -> None:
        now = time.monotonic()
        if now - last[0] >= 0.2 or fraction >= 1.0:
            last[0] = now
            conn.send(("progress", float(fraction), str(stage)))

    try:
        blobs = open_blob_store(settings)
        if memory:
            _warm_blas()  # BLAS allocates its buffers now: under the limit it may hang instead of failing
            resource.setrlimit(resource.RLIMIT_AS, (memory, resource.RLIM_INFINITY))
        result = STAGES[job["kind"]](job, blobs, settings, progress, workdir,
                                     partial=lambda part: conn.send(("partial", part)))
        conn.send(("done", result))
    except InputError as exc:
        conn.send(("error", exc.code, str(exc), False))
    except MemoryError as exc:  # the same limit fails the same way: not retried
        conn.send(("error", "out_of_memory", str(job_out_of_memory(exc, job["kind"], memory)), False))
    except DETERMINISTIC as exc:  # the job is deterministic: the same input fails the same way again
        traceback.print_exc()
        conn.send(("error", "computation_error", computation_error(exc, job["kind"]), False))
    except Exception as exc:  # noqa: BLE001 - unexpected (I/O, the blob store): reported for a retry
        traceback.print_exc()
        conn.send(("error", type(exc).__name__, f"{type(exc).__name__}: {exc}", True))
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
        sys.stderr.flush()


DETERMINISTIC = (ArithmeticError, ValueError, LookupError, TypeError, AssertionError)
"""Errors of a stage's computation (not of I/O): jobs are deterministic for the same input and seed, so
these recur on every attempt and fail the job at once (error code ``computation_error``) instead of after
PDEANIM_MAX_ATTEMPTS tries."""


def computation_error(exc: BaseException, kind: str) -> str:
    """The message of a deterministic failure: the error, where it was raised, and that it is final."""
    frames = traceback.extract_tb(exc.__traceback__)
    where = ""
    if frames:
        where = f" at {'/'.join(Path(frames[-1].filename).parts[-2:])}:{frames[-1].lineno}"
    return (f"the {kind} job failed with {type(exc).__name__}: {exc}{where}; not retried (the same input "
            "fails the same way): the input or parameters reach a case the checks at submission do not "
            "catch yet")


MEMORY_ADVICE = {"simulate": "lower frames or target_tets", "fit": "fit fewer frames or a coarser mesh",
                 "cyclic": "lower frames, n_curves or points", "export": "export at a lower fps"}
"""What to lower, per job kind, when a job runs out of memory."""


def job_out_of_memory(exc: MemoryError, kind: str, memory: int) -> Exception:
    """The OutOfMemoryError of a job: the failed allocation, the job's limit and the settings that help
    (everything it needs is imported already: it runs where memory ran out)."""
    lower = MEMORY_ADVICE.get(kind, "lower the job's sizes")
    if not memory:
        return out_of_memory(exc, f"{lower}, or set PDEANIM_JOB_MEMORY_BYTES on a machine with more memory")
    return out_of_memory(exc, f"{lower}, or raise PDEANIM_JOB_MEMORY_BYTES (now {memory} bytes) or "
                              "PDEANIM_JOB_MEMORY_FRACTION", (memory, "job memory limit"))


@dataclass
class Outcome:
    """How an attempt ended: ``done`` (result), ``error`` (code, message, retry), ``lost``, ``stopped``."""

    status: str
    result: dict | None = None
    code: str = ""
    message: str = ""
    retry: bool = True
    partial: dict | None = None  # result ids stored mid-attempt (with "next_stage"), if any
