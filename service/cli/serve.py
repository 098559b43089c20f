"""``pdeanim serve [--host H] [--port P]``: migrate the database (embedded default) and run the API,
optionally with job workers started alongside (``--with-workers N``: the embedded one-command setup)."""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys

from pdeanim_service.console import CONSOLE
from pdeanim_service.store.scratch import die_with_parent

WORKER_CMD = [*CONSOLE, "worker"]


def register(subparsers) -> None:  # noqa: ANN001
    """Add the ``serve`` sub-command."""
    p = subparsers.add_parser(
        "serve", help="run the HTTP API (settings from PDEANIM_* environment variables)"
    )
    p.add_argument("--host", default="127.0.0.1", help="interface to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    p.add_argument("--workers", type=int, default=None,
                   help="HTTP processes (uvicorn workers; default: the CPUs this process may use, "
                        f"{default_http_workers()} here); each keeps its own clip and frame caches")
    p.add_argument("--with-workers", type=int, default=0, metavar="N",
                   help="also start N job workers (`pdeanim worker`) and stop them on exit (default 0)")
    p.add_argument("--no-migrate", action="store_true",
                   help="do not run migrations first (scale-out: a `serve --migrate-only` step runs them)")
    p.add_argument("--migrate-only", action="store_true", help="run the database migrations and exit")
    p.add_argument("--log-level", default="info",
                   help="info (default): where it listens and one access line per request; warning: quiet")
    p.set_defaults(func=run)


def default_http_workers() -> int:
    """The number of CPUs this process may run on (its affinity mask), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def http_app():  # noqa: ANN201 - a FastAPI app
    """The app of one HTTP process (uvicorn ``factory=True``). Under a supervisor (``--workers`` > 1, each
    process started by uvicorn's multiprocessing supervisor), the process first arranges to die with it, so
    a SIGKILLed ``pdeanim serve`` leaves no HTTP process holding its port."""
    import multiprocessing

    from pdeanim_service.api.app import app_from_environment

    supervisor = multiprocessing.parent_process()
    if supervisor is not None and supervisor.pid is not None:
        die_with_parent(supervisor.pid)
    return app_from_environment()


def _die_with_serve(pid: int):  # noqa: ANN202 - a preexec function
    """preexec_fn of the job workers started by ``--with-workers``: they die with this process."""
    def arm() -> None:  # runs between fork and exec: nothing to import here
        die_with_parent(pid)

    return arm


def _stop(procs: list[subprocess.Popen]) -> None:
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    for proc in procs:
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            proc.kill()


def log_config(level: str) -> dict:
    """uvicorn's logging config plus the pdeanim loggers (access lines, errors) on stderr, in every
    process."""
    from copy import deepcopy

    from uvicorn.config import LOGGING_CONFIG

    config = deepcopy(LOGGING_CONFIG)
    config["formatters"]["pdeanim"] = {"format": "%(asctime)s %(levelname)s %(name)s: %(message)s"}
    config["handlers"]["pdeanim"] = {"class": "logging.StreamHandler", "formatter": "pdeanim",
                                     "stream": "ext://sys.stderr"}
    config["loggers"]["pdeanim"] = {"handlers": ["pdeanim"], "level": level.upper(), "propagate": False}
    return config


def run(args: argparse.Namespace) -> int:
    """Migrate (unless --no-migrate), start the job workers asked for, then serve until interrupted."""
    import uvicorn

    from pdeanim_service.settings import Settings
    from pdeanim_service.store.db import migrate

    settings = Settings()
    if not args.no_migrate:
        migrate(settings.resolved_database_url())
    if args.migrate_only:
        print("pdeanim serve: database is at the newest schema")
        return 0
    http_workers = args.workers or default_http_workers()
    print(f"pdeanim serve: listening on http://{args.host}:{args.port} (data {settings.resolved_data_dir()}, "
          f"{http_workers} HTTP worker(s), {max(args.with_workers, 0)} job worker(s))", file=sys.stderr,
          flush=True)
    workers = [subprocess.Popen(WORKER_CMD, preexec_fn=_die_with_serve(os.getpid()))
               for _ in range(max(args.with_workers, 0))]
    # uvicorn re-raises SIGTERM/SIGINT after its graceful shutdown; with these handlers in place the
    # re-raised signal lands here instead of killing the process, so the workers are stopped and we exit 0.
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: None)
    try:
        uvicorn.run(**uvicorn_options(args, settings, http_workers))
    finally:
        _stop(workers)
    return 0


def uvicorn_options(args: argparse.Namespace, settings, http_workers: int) -> dict:  # noqa: ANN001 - Settings
    """The keyword arguments of ``uvicorn.run`` (and ``uvicorn.Config``) for these arguments and settings,
    the supervisor's health-check timeout included (``PDEANIM_HTTP_WORKER_HEALTHCHECK_SECONDS``)."""
    return {"app": "pdeanim_service.cli.serve:http_app", "factory": True, "host": args.host,
            "port": args.port,
            "workers": http_workers, "log_level": args.log_level, "access_log": False,
            "log_config": log_config(args.log_level),
            "timeout_worker_healthcheck": settings.http_worker_healthcheck_seconds}
