"""``pdeanim serve`` on a loaded host: the supervisor's health-check timeout of its HTTP processes comes from
``PDEANIM_HTTP_WORKER_HEALTHCHECK_SECONDS`` (uvicorn's own 5 s killed processes that were still starting),
and the start-up line names the number of HTTP processes also when ``--workers`` is not given."""

from __future__ import annotations

import argparse
import os
import re
import signal
import time

import pytest
import uvicorn

from pdeanim_service.cli.serve import default_http_workers, uvicorn_options
from pdeanim_service.settings import Settings

from .harness import Services
from .test_worker import children


def _args(**values) -> argparse.Namespace:
    base = {"host": "127.0.0.1", "port": 0, "workers": None, "log_level": "warning"}
    return argparse.Namespace(**{**base, **values})


def test_the_setting_reaches_uvicorns_config(monkeypatch):
    monkeypatch.setenv("PDEANIM_HTTP_WORKER_HEALTHCHECK_SECONDS", "75")
    config = uvicorn.Config(**uvicorn_options(_args(), Settings(), 3))
    assert config.timeout_worker_healthcheck == 75 and config.workers == 3
    monkeypatch.delenv("PDEANIM_HTTP_WORKER_HEALTHCHECK_SECONDS")
    assert Settings().http_worker_healthcheck_seconds == 120.0  # the default: far above uvicorn's 5 s


def _http_processes(pid: int) -> list[int]:
    return [p for p in children(pid) if b"spawn_main" in open(f"/proc/{p}/cmdline", "rb").read()]


@pytest.mark.slow
def test_a_real_supervisor_applies_the_setting(backend, tmp_path):
    """With a 1 s timeout, an HTTP process stopped (SIGSTOP) for longer is killed and replaced: the setting
    reached the running supervisor (at uvicorn's 5 s default it would have survived the 3 s stop)."""
    svc = Services(backend, tmp_path / "logs", env_extra={"PDEANIM_HTTP_WORKER_HEALTHCHECK_SECONDS": "1",
                                                           "PDEANIM_WARM_START": "false"})
    svc.start_server("--workers", "2")
    try:
        deadline = time.monotonic() + 60
        while len(http := _http_processes(svc.server.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        victim = http[0]
        os.kill(victim, signal.SIGSTOP)
        deadline = time.monotonic() + 3
        while victim in _http_processes(svc.server.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        if victim in _http_processes(svc.server.pid):
            os.kill(victim, signal.SIGCONT)
        assert victim not in _http_processes(svc.server.pid), "a process silent for 3 s was kept"
        deadline = time.monotonic() + 30  # the supervisor logs it right after reaping the process
        while f"Child process [{victim}] died" not in svc.log("server") and time.monotonic() < deadline:
            time.sleep(0.1)
        assert f"Child process [{victim}] died" in svc.log("server"), svc.log("server")[-2000:]
        line = re.search(r"\((?:data [^,]*), (\S+) HTTP worker\(s\)", svc.log("server"))
        assert line and line.group(1) == "2", svc.log("server")[-2000:]
    finally:
        svc.stop()


@pytest.mark.slow
def test_the_startup_line_names_the_default_process_count(backend, tmp_path):
    svc = Services(backend, tmp_path / "logs", env_extra={"PDEANIM_WARM_START": "false"})
    svc.start_server()
    try:
        line = re.search(r"(\S+) HTTP worker\(s\)", svc.log("server"))
        assert line and line.group(1) == str(default_http_workers()), svc.log("server")[-2000:]
    finally:
        svc.stop()
