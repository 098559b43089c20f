"""Real processes for the integration tests: ``pdeanim serve`` on a free port and ``pdeanim worker``s."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx

from .conftest import Backend, free_port

ROOT = Path(__file__).resolve().parents[2]
PDEANIM = [sys.executable, "-m", "service.cli"]


def process_env(backend: Backend, **extra: str) -> dict[str, str]:
    """The environment of a service process on ``backend`` (fast polls for tests). The lease is 10 s, not the
    fastest the tests could use: on a loaded machine a 3 s lease expired between heartbeats and the job ran
    a second attempt that tests asserting ``attempt == 1`` saw."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PDEANIM_LEASE_SECONDS": "10", "PDEANIM_POLL_SECONDS": "0.2",
           "PDEANIM_BACKOFF_SECONDS": "0.5", "PDEANIM_SHUTDOWN_GRACE_SECONDS": "5", **backend.env, **extra}
    return env


@dataclass
class Services:
    """A running API server and its workers."""

    backend: Backend
    log_dir: Path
    port: int = 0
    server: subprocess.Popen | None = None
    workers: list[subprocess.Popen] = field(default_factory=list)
    env_extra: dict[str, str] = field(default_factory=dict)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def _spawn(self, args: list[str], name: str) -> subprocess.Popen:
        log = open(self.log_dir / f"{name}.log", "ab")  # noqa: SIM115 - closed with the process
        return subprocess.Popen(PDEANIM + args, env=process_env(self.backend, **self.env_extra), stdout=log,
                                stderr=subprocess.STDOUT, cwd=self.log_dir)

    def start_server(self, *extra: str) -> None:
        self.port = free_port()
        self.server = self._spawn(["serve", "--port", str(self.port), *extra], "server")
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if self.server.poll() is not None:
                raise RuntimeError(f"server exited: {(self.log_dir / 'server.log').read_text()[-3000:]}")
            try:
                if httpx.get(self.url + "/healthz", timeout=1).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise RuntimeError("server did not become healthy in 60 s")

    def start_worker(self) -> subprocess.Popen:
        proc = self._spawn(["worker", "--log-level", "INFO"], f"worker{len(self.workers)}")
        self.workers.append(proc)
        return proc

    def logs(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text()[-4000:]}" for p in sorted(self.log_dir.glob("*.log")))

    def stop(self) -> None:
        for proc in [*self.workers, self.server]:
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in [*self.workers, self.server]:
            if proc is None:
                continue
            try:
                proc.wait(15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)


def make_key(backend: Backend, tenant: str) -> str:
    """A new API key for ``tenant`` (in-process, on the backend's database)."""
    from service.store.context import Store
    from service.store.tenants import create_key

    store = Store.open(backend.settings(), run_migrations=True)
    try:
        with store.sessions() as session:
            key, _ = create_key(session, tenant)
            session.commit()
        return key
    finally:
        store.close()


def client(services: Services, key: str | None) -> httpx.Client:
    headers = {"Authorization": f"Bearer {key}"} if key else {}
    return httpx.Client(base_url=services.url, headers=headers, timeout=60)


def wait_job(api: httpx.Client, job_id: str, timeout: float = 120) -> dict:
    """Poll a job until it succeeds or fails."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = api.get(f"/v1/jobs/{job_id}").json()
        if job["state"] in ("succeeded", "failed"):
            return job
        time.sleep(0.2)
    raise TimeoutError(f"job {job_id} still {job['state']} after {timeout} s: {job}")
