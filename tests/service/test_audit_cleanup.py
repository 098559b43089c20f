"""Audit defect 7: scratch left by killed processes is removed. A SIGKILLed upload's temp file goes when the
API starts again; a killed attempt's work directory goes right after the attempt; a SIGKILLed worker's goes
when a worker starts again. Real processes, real signals."""

from __future__ import annotations

import os
import signal
import socket
import time
from pathlib import Path

import pytest

from .conftest import Backend
from .harness import Services, client, make_key


def wait_for(condition, timeout: float = 60.0, what: str = "condition"):  # noqa: ANN001
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.1)
    raise TimeoutError(f"{what} not reached in {timeout} s")


@pytest.fixture
def svc(tmp_path):
    s = Services(Backend("sqlite", {"PDEANIM_DATA_DIR": str(tmp_path / "data")}), tmp_path)
    yield s
    s.stop()


def uploads(tmp: Path) -> list[Path]:
    return sorted(tmp.glob("upload-*"))


def test_killed_upload_temp_file_removed_at_start(svc, tmp_path):
    # one process: SIGKILL then kills the process that handles the upload (with several uvicorn workers an
    # orphaned worker could finish the request and remove its file, and the crash would not be reproduced)
    svc.start_server("--workers", "1")
    key = make_key(svc.backend, "t")
    tmp = tmp_path / "data" / "tmp"
    sock = socket.create_connection(("127.0.0.1", svc.port))
    head = (f"POST /v1/meshes HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {key}\r\n"
            "Content-Type: multipart/form-data; boundary=BB\r\nContent-Length: 10000000\r\n\r\n"
            '--BB\r\nContent-Disposition: form-data; name="file"; filename="a.obj"\r\n\r\n')
    sock.sendall(head.encode() + b"v 0 0 0\n" * 20_000)
    wait_for(lambda: uploads(tmp) and uploads(tmp)[0].stat().st_size > 0, what="the upload's temp file")
    svc.server.send_signal(signal.SIGKILL)
    svc.server.wait(30)
    sock.close()
    assert uploads(tmp), "the killed upload left no file: the test does not reproduce the crash"
    svc.start_server()
    assert not uploads(tmp), uploads(tmp)


def descendants(pid: int, depth: int = 99) -> list[int]:
    """Every process below ``pid`` down to ``depth`` generations (from /proc)."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parents[int(entry.name)] = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
    out, frontier = [], [pid]
    for _ in range(depth):
        children = [p for p, pp in parents.items() if pp in frontier]
        out += children
        frontier = children
    return out


def address_space_limit(pid: int) -> int:
    """The soft RLIMIT_AS of ``pid`` in bytes (0 when unlimited)."""
    try:
        text = Path(f"/proc/{pid}/limits").read_text()
    except OSError:
        return 0  # gone already
    for line in text.splitlines():
        if line.startswith("Max address space"):
            soft = line.split()[3]
            return 0 if soft == "unlimited" else int(soft)
    raise AssertionError(f"no address space line for {pid}")


def test_killed_attempt_and_worker_leave_no_work_dirs(svc, tmp_path, data_dir):
    svc.start_server()
    worker = svc.start_worker()
    tmp = tmp_path / "data" / "tmp"
    with client(svc, make_key(svc.backend, "t")) as api:
        spot = (data_dir / "spot.obj").read_bytes()
        mesh = api.post("/v1/meshes", files={"file": ("spot.obj", spot)}).json()
        job = api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh["id"],
                                         "params": {"frames": 2000, "target_tets": 2000}}).json()

        def work_dirs() -> set[Path]:
            return {p for p in tmp.iterdir() if p.is_dir() and job["id"] in p.name}

        first = wait_for(work_dirs, what="the first attempt's work directory")
        wait_for(lambda: api.get(f"/v1/jobs/{job['id']}").json()["state"] == "running", what="running")
        # the attempt's process runs below the worker's forkserver: kill it (and what it started), not
        # the worker
        def attempt_limits() -> dict[int, int]:
            procs = set(descendants(worker.pid)) - set(descendants(worker.pid, depth=1))
            limits = {pid: address_space_limit(pid) for pid in procs}
            return limits if limits and all(limits.values()) else {}

        # defect 6: with no memory setting, the job still runs under a limit (half the machine's memory)
        limits = wait_for(attempt_limits, what="a memory limit on the attempt's process")
        physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        assert all(lim <= max(physical // 2, 2 * 1024**3) for lim in limits.values()), limits
        attempt = set(limits)
        for pid in attempt:
            os.kill(pid, signal.SIGKILL)
        wait_for(lambda: not (first & work_dirs()), what="the killed attempt's work directory removed")
        second = wait_for(lambda: work_dirs() - first, what="the retry's work directory")
        below = descendants(worker.pid)  # the whole worker dies at once, as under the OOM killer
        for pid in [worker.pid, *below]:
            os.kill(pid, signal.SIGKILL)
        worker.wait(30)
        assert second & work_dirs(), "the killed worker left no work directory: not reproduced"
        svc.start_worker()
        wait_for(lambda: not (second & work_dirs()), what="the dead worker's work directory removed at start")
