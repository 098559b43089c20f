"""Run ``pdeanim serve`` and ``pdeanim worker`` as child processes on a free loopback port: start, wait until
``/healthz`` answers, stop with SIGTERM. One launcher for the demo, the frame benchmark and the tests."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
from pathlib import Path

import httpx

from pdeanim_service.console import CONSOLE


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Launcher:
    """An API server and its workers; each process logs to ``log_dir/NAME.log`` (server, worker0, ...)."""

    def __init__(self, log_dir: Path, env: dict[str, str] | None = None, cwd: Path | None = None) -> None:
        self.log_dir, self.cwd = Path(log_dir), cwd
        self.env = dict(os.environ if env is None else env)
        self.port = 0
        self.server: subprocess.Popen | None = None
        self.workers: list[subprocess.Popen] = []

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def environment(self) -> dict[str, str]:
        """The environment of the next process started (subclasses may compute it per start)."""
        return self.env

    def spawn(self, args: list[str], name: str) -> subprocess.Popen:
        """Start ``pdeanim ARGS`` with its output appended to ``log_dir/NAME.log``."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        with open(self.log_dir / f"{name}.log", "ab") as log:  # the child keeps its own descriptor
            return subprocess.Popen(CONSOLE + args, env=self.environment(), stdout=log,
                                    stderr=subprocess.STDOUT, cwd=self.cwd)

    def start_server(self, *extra: str, timeout: float = 120.0) -> str:
        """Start the API server on a free port and wait until /healthz answers 200; returns its URL."""
        self.port = free_port()
        self.server = self.spawn(["serve", "--port", str(self.port), *extra], "server")
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.server.poll() is not None:
                raise RuntimeError(f"the API server exited: {self.log('server')[-3000:]}")
            try:
                if httpx.get(self.url + "/healthz", timeout=5).status_code == 200:
                    return self.url
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise RuntimeError(f"the API server did not answer /healthz within {timeout:.0f} s; "
                           f"see {self.log_dir}")

    def start_worker(self, *extra: str) -> subprocess.Popen:
        """Start one more ``pdeanim worker`` (log ``worker<N>.log``)."""
        proc = self.spawn(["worker", *extra], f"worker{len(self.workers)}")
        self.workers.append(proc)
        return proc

    def log(self, name: str) -> str:
        path = self.log_dir / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def logs(self) -> str:
        """The tail of every process's log, for failure messages."""
        return "\n".join(f"--- {p.name}\n{p.read_text(errors='replace')[-4000:]}"
                         for p in sorted(self.log_dir.glob("*.log")))

    def stop(self, grace: float = 30.0) -> None:
        """SIGTERM every process, wait up to ``grace`` seconds each, then kill what is left."""
        procs = [p for p in [*self.workers, self.server] if p is not None]
        for proc in procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in procs:
            try:
                proc.wait(grace)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(10)
