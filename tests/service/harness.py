"""Real processes for the integration tests: ``pdeanim serve`` on a free port and ``pdeanim worker``s, started
with the launcher the demo uses."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import httpx

from pdeanim_service.launcher import Launcher

from .conftest import Backend

ROOT = Path(__file__).resolve().parents[2]
PDEANIM = [sys.executable, "-m", "pdeanim_service.cli"]


def process_env(backend: Backend, **extra: str) -> dict[str, str]:
    """The environment of a service process on ``backend`` (fast polls for tests). The lease is 10 s, not the
    fastest the tests could use: on a loaded machine a 3 s lease expired between heartbeats and the job ran
    a second attempt that tests asserting ``attempt == 1`` saw."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PDEANIM_LEASE_SECONDS": "10",
           "PDEANIM_POLL_SECONDS": "0.2",
           "PDEANIM_BACKOFF_SECONDS": "0.5", "PDEANIM_SHUTDOWN_GRACE_SECONDS": "5", **backend.env, **extra}
    return env


class Services(Launcher):
    """A running API server and its workers on ``backend`` (the shared
    :class:`pdeanim_service.launcher.Launcher`);
    ``env_extra`` may change between starts and applies to the processes started after it."""

    def __init__(self, backend: Backend, log_dir: Path, env_extra: dict[str, str] | None = None) -> None:
        super().__init__(log_dir, cwd=log_dir)
        self.backend, self.env_extra = backend, dict(env_extra or {})

    def environment(self) -> dict[str, str]:
        return process_env(self.backend, **self.env_extra)

    def start_worker(self, *extra: str):  # noqa: ANN201 - subprocess.Popen
        return super().start_worker("--log-level", "INFO", *extra)

    def stop(self, grace: float = 15.0) -> None:
        super().stop(grace)


def make_key(backend: Backend, tenant: str) -> str:
    """A new API key for ``tenant`` (in-process, on the backend's database)."""
    from pdeanim_service.store.tenants import issue_key

    return issue_key(backend.settings(), tenant)


def client(services: Services, key: str | None) -> httpx.Client:
    headers = {"Authorization": f"Bearer {key}"} if key else {}
    return httpx.Client(base_url=services.url, headers=headers, timeout=60)


def wait_job(api: httpx.Client, job_id: str, timeout: float = 300) -> dict:
    """Poll a job until it succeeds or fails (a generous deadline: the machine may be loaded)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = api.get(f"/v1/jobs/{job_id}").json()
        if job["state"] in ("succeeded", "failed"):
            return job
        time.sleep(0.2)
    raise TimeoutError(f"job {job_id} still {job['state']} after {timeout} s: {job}")
