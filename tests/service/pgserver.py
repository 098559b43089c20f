"""The PostgreSQL server of the tests: the one on ``PDEANIM_TEST_PG`` (default 127.0.0.1:5432, trust auth)
if it answers, else a throwaway cluster that the tests start themselves (initdb + pg_ctl in a temporary
directory on a free port, as the ``postgres`` user when run as root) and stop at the end of the session."""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

from pdeanim_service.launcher import free_port

DEFAULT = "127.0.0.1:5432"


@dataclass
class PgServer:
    """Where a PostgreSQL server listens (user ``postgres``, trust auth), and how to stop one we started."""

    host: str
    port: int
    data_dir: Path | None = None  # set when the tests started this cluster
    run_as: list[str] | None = None

    def dsn(self, dbname: str = "postgres") -> str:
        return f"host={self.host} port={self.port} user=postgres dbname={dbname}"

    def url(self, dbname: str) -> str:
        return f"postgresql+psycopg://postgres@{self.host}:{self.port}/{dbname}"

    def stop(self) -> None:
        if self.data_dir is None:
            return
        subprocess.run([*(self.run_as or []), _tool("pg_ctl"), "-D", str(self.data_dir / "db"),
                        "-m", "immediate", "-w", "stop"], capture_output=True, check=False, timeout=120)
        shutil.rmtree(self.data_dir, ignore_errors=True)


def _reachable(host: str, port: int) -> str | None:
    """None if a PostgreSQL server answers there, else why not."""
    try:
        import psycopg

        with psycopg.connect(f"host={host} port={port} user=postgres dbname=postgres", connect_timeout=10):
            return None
    except Exception as exc:  # noqa: BLE001 - any failure means: not usable
        return f"PostgreSQL on {host}:{port} is unreachable ({type(exc).__name__}: {exc})"


def _tool(name: str) -> str:
    """A PostgreSQL server program from PATH or Debian's /usr/lib/postgresql/*/bin."""
    debian = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"), reverse=True)
    found = shutil.which(name) or (debian[0] if debian else None)
    if not found:
        raise FileNotFoundError(f"{name} is not installed (apt-get install postgresql)")
    return found


def _throwaway() -> PgServer:
    """initdb + pg_ctl start in a fresh temporary directory; raises with the reason on failure."""
    initdb, pg_ctl = _tool("initdb"), _tool("pg_ctl")
    root = Path(tempfile.mkdtemp(prefix="pdeanim-pg-"))
    run_as: list[str] = []
    if os.geteuid() == 0:  # PostgreSQL refuses to run as root
        user = pwd.getpwnam("postgres")
        os.chown(root, user.pw_uid, user.pw_gid)
        run_as = ["runuser", "-u", "postgres", "--"]
    port = free_port()
    server = PgServer("127.0.0.1", port, root, run_as)
    try:
        subprocess.run([*run_as, initdb, "-D", str(root / "db"), "-U", "postgres", "--auth=trust",
                        "-E", "UTF8"], capture_output=True, check=True, timeout=300)
        subprocess.run([*run_as, pg_ctl, "-D", str(root / "db"), "-l", str(root / "log"), "-w", "-t", "120",
                        "-o", f"-p {port} -k {root} -c listen_addresses=127.0.0.1 -c fsync=off", "start"],
                       capture_output=True, check=True, timeout=180)
    except (OSError, subprocess.SubprocessError) as exc:
        detail = getattr(exc, "stderr", b"") or b""
        server.stop()
        why = detail.decode(errors="replace")
        raise RuntimeError(f"could not start a throwaway PostgreSQL: {exc} {why}") from exc
    return server


def start_or_find() -> tuple[PgServer | None, str]:
    """The server to use and, when there is none, the reason."""
    host, _, port = os.environ.get("PDEANIM_TEST_PG", DEFAULT).rpartition(":")
    reason = _reachable(host, int(port))
    if reason is None:
        return PgServer(host, int(port)), ""
    try:
        server = _throwaway()
    except (FileNotFoundError, KeyError, RuntimeError) as exc:
        return None, f"{reason}; {exc}"
    again = _reachable(server.host, server.port)
    if again is not None:
        server.stop()
        return None, f"{reason}; the throwaway PostgreSQL did not answer: {again}"
    return server, ""
