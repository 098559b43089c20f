"""Processes die with the process that started them, with real processes and SIGKILL: a job process with its
worker (the parent-death signal, PR_SET_PDEATHSIG), and the HTTP processes and job workers of
``pdeanim serve`` with it, so a restart binds its port at once."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import httpx

from pdeanim_service.store.scratch import alive

from .harness import ROOT, Services, client, make_key
from .test_worker import HEAVY, children, job_processes, submit, wait_state

POSTGRES_NIGHTLY = True  # process lifecycle, the same on both backends: CI runs it on SQLite (conftest)

GONE_SECONDS = 15.0  # they die within about a second; the margin is for a loaded machine


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (children, their children, ...)."""
    out, todo = [], [pid]
    while todo:
        kids = children(todo.pop())
        out += kids
        todo += kids
    return out


def wait_gone(pids: list[int], timeout: float = GONE_SECONDS) -> list[int]:
    """Wait until none of ``pids`` runs (exited, or a zombie nobody reaped yet); the ones still running."""
    deadline = time.monotonic() + timeout
    while (running := [p for p in pids if alive(p)]) and time.monotonic() < deadline:
        time.sleep(0.05)
    return running


def wait_healthy(url: str, proc, timeout: float = 120.0) -> None:  # noqa: ANN001 - subprocess.Popen
    """Wait until ``url``/healthz answers 200 (fail at once if the server exits)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, f"the server exited with {proc.returncode}"
        try:
            if httpx.get(url + "/healthz", timeout=5).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    raise TimeoutError(f"{url} did not answer /healthz within {timeout} s")


def test_a_zombie_is_not_alive_and_die_with_parent_kills_the_child():
    """A process killed but not reaped yet counts as gone; a child that armed the parent-death signal dies
    with its parent (here a middle process that exits at once)."""
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 30
    while alive(proc.pid) and time.monotonic() < deadline:  # exited, still unreaped: a zombie
        time.sleep(0.02)
    assert not alive(proc.pid) and Path(f"/proc/{proc.pid}").exists()
    proc.wait()
    script = ("import os, subprocess, sys\n"
              "from pdeanim_service.store.scratch import die_with_parent\n"
              "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(600)'], "
              "stdout=subprocess.DEVNULL, "
              "preexec_fn=lambda: die_with_parent(os.getppid()))\n"
              "print(child.pid, flush=True)\n")  # and exit at once, leaving the sleeper
    middle = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert middle.returncode == 0, middle.stderr
    assert wait_gone([int(middle.stdout.split()[0])]) == [], "the child outlived its parent"


def test_sigkilled_worker_takes_its_job_process_along(backend, tmp_path, data_dir):
    svc = Services(backend, tmp_path / "logs")
    svc.start_server()
    try:
        with client(svc, make_key(backend, "lifecycle")) as api:
            r = api.post("/v1/meshes", files={"file": ("spot.obj", (data_dir / "spot.obj").read_bytes())})
            mesh_id = r.json()["id"]
            for _ in range(3):  # the defect showed in 1 run of 6
                job_id = submit(api, mesh_id, HEAVY)
                worker = svc.start_worker()
                assert wait_state(api, job_id, ("running", "succeeded"))["state"] == "running"
                deadline = time.monotonic() + 120
                while not (jobs := job_processes(worker.pid)) and time.monotonic() < deadline:
                    time.sleep(0.05)
                assert jobs, "the job process never started"
                os.kill(worker.pid, signal.SIGKILL)  # not reaped yet: the worker stays a zombie meanwhile
                assert wait_gone(jobs) == [], "a job process outlived its SIGKILLed worker"
                worker.wait(30)
                api.post(f"/v1/jobs/{job_id}/cancel")
    finally:
        svc.stop()


def test_sigkilled_serve_takes_its_http_processes_along_and_a_restart_binds_the_port(backend, tmp_path):
    svc = Services(backend, tmp_path / "logs")
    svc.start_server("--workers", "2", "--with-workers", "1")
    try:
        below = descendants(svc.server.pid)
        http = [p for p in children(svc.server.pid) if b"multiprocessing" in Path(f"/proc/{p}/cmdline")
                .read_bytes()]
        assert len(http) >= 2, below  # two HTTP processes (and the job worker with its forkserver)
        os.kill(svc.server.pid, signal.SIGKILL)
        assert wait_gone(below) == [], "processes of the SIGKILLed serve kept running"
        svc.server.wait(30)
        again = svc.spawn(["serve", "--port", str(svc.port), "--workers", "2"], "server-restarted")
        try:
            wait_healthy(svc.url, again)
        finally:
            again.send_signal(signal.SIGTERM)
            assert again.wait(60) == 0
        assert "Address already in use" not in svc.log("server-restarted")
    finally:
        svc.stop()
