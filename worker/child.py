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

from service.store.scratch import alive

PRELOAD = ["numpy", "scipy.sparse", "scipy.linalg", "trimesh", "worker.stages"]


def child_context() -> multiprocessing.context.BaseContext:
    """A forkserver context that preloads the heavy libraries once, so each attempt starts fast and clean."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(PRELOAD)
    return ctx


def _watch_parent(parent_pid: int) -> None:
    while True:
        time.sleep(1.0)
        if os.getppid() == 1 or not alive(parent_pid):
            os._exit(3)  # the worker is gone: nobody will take our result


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
    """Entry point of the child: run the job's stage, send the outcome on ``conn``, and exit at once."""
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
    from service.settings import Settings
    from service.store.blobs import open_blob_store

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
    except MemoryError:
        conn.send(("error", "out_of_memory", f"the job needs more memory than its limit of "
                   f"{memory / 2**30:.2f} GiB ({memory} bytes; PDEANIM_JOB_MEMORY_BYTES or "
                   f"PDEANIM_JOB_MEMORY_FRACTION): lower "
                   "frames, target_tets or the poses' size, or raise the limit", True))
    except Exception as exc:  # noqa: BLE001 - unexpected: reported for a retry
        traceback.print_exc()
        conn.send(("error", type(exc).__name__, f"{type(exc).__name__}: {exc}", True))
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
        sys.stderr.flush()


@dataclass
class Outcome:
    """How an attempt ended: ``done`` (result), ``error`` (code, message, retry), ``lost``, ``stopped``."""

    status: str
    result: dict | None = None
    code: str = ""
    message: str = ""
    retry: bool = True
    partial: dict | None = None  # result ids stored mid-attempt (with "next_stage"), if any
